/* The twin of fleet_sim.model.kinematics.speed_bounds and distance_at: where an AGV is t seconds
   into a hop's closed-form trapezoid profile. Same formulas, same order of operations; the tests
   hold the two together. Pieces are [length_m, speed_limit_mps] pairs. */
var FleetKinematics = (function () {
  'use strict';

  function speedBounds(pieces, vIn, vEndMax, accel, decel) {
    var n = pieces.length;
    var bounds = new Array(n + 1).fill(0);
    bounds[0] = vIn;
    for (var i = 1; i < n; i++) bounds[i] = Math.min(pieces[i - 1][1], pieces[i][1]);
    bounds[n] = Math.min(vEndMax, pieces[n - 1][1]);
    for (i = 1; i <= n; i++) {  // forward: what acceleration can reach
      var reach = Math.sqrt(bounds[i - 1] * bounds[i - 1] + 2.0 * accel * pieces[i - 1][0]);
      if (reach < bounds[i]) bounds[i] = reach;
    }
    for (i = n - 1; i > 0; i--) {  // backward: what braking allows
      var brake = Math.sqrt(bounds[i + 1] * bounds[i + 1] + 2.0 * decel * pieces[i][0]);
      if (brake < bounds[i]) bounds[i] = brake;
    }
    return bounds;
  }

  function distanceAt(pieces, vIn, vEnd, accel, decel, t) {
    var bounds = speedBounds(pieces, vIn, vEnd, accel, decel);
    var done = 0.0;
    var left = t;
    for (var i = 0; i < pieces.length; i++) {
      var length = pieces[i][0], limit = pieces[i][1];
      if (length <= 0.0) continue;
      var v0 = bounds[i], v1 = bounds[i + 1];
      var vPeakSq = (2.0 * accel * decel * length + decel * v0 * v0 + accel * v1 * v1) /
        (accel + decel);
      var vPeak = Math.max(Math.min(limit, Math.sqrt(vPeakSq)), v0, v1);
      var tAcc = (vPeak - v0) / accel;
      var dAcc = (vPeak * vPeak - v0 * v0) / (2.0 * accel);
      var dDec = (vPeak * vPeak - v1 * v1) / (2.0 * decel);
      var cruise = Math.max(0.0, length - dAcc - dDec);
      var tCruise = cruise / vPeak;
      var tDec = (vPeak - v1) / decel;
      if (left >= tAcc + tCruise + tDec) {
        done += length;
        left -= tAcc + tCruise + tDec;
        continue;
      }
      var along;
      if (left < tAcc) along = v0 * left + 0.5 * accel * left * left;
      else if (left < tAcc + tCruise) along = dAcc + vPeak * (left - tAcc);
      else {
        var tau = left - tAcc - tCruise;
        along = dAcc + cruise + vPeak * tau - 0.5 * decel * tau * tau;
      }
      return done + Math.min(Math.max(along, 0.0), length);
    }
    return done;
  }

  /* A drive row's pieces: the curve (if it turns), then the rest of the segment
     (fleet_sim.analysis.replay.hop_pieces). */
  function hopPieces(length, curveM, curveMps, limitMps) {
    if (curveM > 0.0) return [[curveM, curveMps], [length - curveM, limitMps]];
    return [[length, limitMps]];
  }

  return {speedBounds: speedBounds, distanceAt: distanceAt, hopPieces: hopPieces};
})();
