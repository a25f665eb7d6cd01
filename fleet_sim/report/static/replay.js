/* The replay page: the floor (canvas), the controls, the timeline (Gantt) and the lead-time
   chart, from the JSON in #replay-data (fleet_sim.report.replay.page_data; its objects are the
   typedefs below, generated from fleet_sim.report.replay_payload). Every text from the
   data reaches the page as canvas text or textContent, never as markup.

   window.fleetReplay is for tests and the curious: positionsAt(t) (the twin of
   fleet_sim.analysis.replay.positions_at), zonesAt(t) (holders: the twin of zone_holders_at),
   seek(t), drawn (what the last frame drew), timelineTotals(). With #t=SECONDS in the address
   the page seeks there at once and writes its state into the element #replay-check (a pre at
   the end of the body). */
/* ---- the payload: generated from fleet_sim/report/replay_payload.py, do not edit
   (python -m fleet_sim.report.replay_payload rewrites it). */

/**
 * Everything the page draws (`page_data`), in the page as JSON (#replay-data).
 * @typedef {Object} ReplayPayload
 * @property {Meta} meta
 * @property {string[]} states The RSS-AGV-001 states, in index order.
 * @property {string[]} stateColours
 * @property {Nodes} nodes
 * @property {Segs} segs
 * @property {Object<string, number[]>} corridors Each single-track corridor's segments (indices).
 * @property {Places} places
 * @property {Profiles} profiles
 * @property {Agv[]} agv
 * @property {ChargerWaits} chargerWaits
 * @property {Zones} zones
 * @property {ZoneHolds} zoneHolds
 * @property {Block[]} blocks
 * @property {Incidents} incidents
 * @property {Leads} leads
 * @property {string[]} strings Every repeated text once.
 */

/**
 * The run and the window the page shows.
 * @typedef {Object} Meta
 * @property {string} scenario
 * @property {string} layout
 * @property {number} agvs Fleet size.
 * @property {number} seed
 * @property {number} duration_s
 * @property {number} warmup_s
 * @property {number} start_h Clock time at t=0 (hours).
 * @property {number} from_s Start of the window (s since the run's start).
 * @property {number} to_s End of the window.
 * @property {boolean} resimulated The motion was simulated again from config.resolved.yaml (a sweep's run).
 */

/**
 * The layout's nodes, sorted by id; other objects point at them by index.
 * @typedef {Object} Nodes
 * @property {string[]} id
 * @property {number[]} x Metres.
 * @property {number[]} y
 * @property {string[]} kind
 * @property {string[]} colour CSS colour: the place's, else the node kind's.
 * @property {number[]} place Index into places, -1: none.
 */

/**
 * The layout's segments (one per direction), sorted by (from, to).
 * @typedef {Object} Segs
 * @property {number[]} u From node (index).
 * @property {number[]} v To node (index).
 * @property {number[]} len Metres.
 * @property {number[]} twoWay 1 if the reverse segment exists.
 */

/**
 * Stations, chargers and parking areas, sorted by id.
 * @typedef {Object} Places
 * @property {string[]} id
 * @property {string[]} kind
 * @property {number[]} node Its first node (index).
 * @property {number[]} capacity
 */

/**
 * Each distinct hop profile once; drives point at it.
 * @typedef {Object} Profiles
 * @property {number[]} seg Segment (index).
 * @property {number[]} vin Entry speed (m/s).
 * @property {number[]} vout Exit speed (m/s).
 * @property {number[]} cm Branch curve length (m).
 * @property {number[]} cv Branch curve speed (m/s).
 * @property {number[]} lim Speed limit (m/s).
 * @property {number[]} acc Acceleration (m/s2).
 * @property {number[]} dec Deceleration (m/s2).
 */

/**
 * One AGV, cut to the window.
 * @typedef {Object} Agv
 * @property {number} id
 * @property {number} length_m
 * @property {AgvPlacements} p
 * @property {AgvSpells} s
 * @property {AgvOrders} o
 * @property {AgvSoc} b
 * @property {AgvWaits} w
 */

/**
 * Where an AGV is: its drives and placements in time order.
 * @typedef {Object} AgvPlacements
 * @property {number[]} t Start (s).
 * @property {number[]} e End (s).
 * @property {number[]} k Kind: 0 drive, 1 on the track, 2 in parking, 3 off the track.
 * @property {number[]} a A drive's profile (index), else its node (index).
 * @property {number[]} d Seconds of the drive actually driven (less than the hop when paused).
 */

/**
 * The AGV's state spells (the timeline).
 * @typedef {Object} AgvSpells
 * @property {number[]} t
 * @property {number[]} e
 * @property {number[]} st State (index into states).
 * @property {number[]} ev Event that started it (index into strings).
 * @property {number[]} det Its detail (index into strings).
 * @property {number[]} o Order held, -1: none.
 * @property {number[]} l 1: loaded.
 */

/**
 * The order the AGV holds, from each time on.
 * @typedef {Object} AgvOrders
 * @property {number[]} t
 * @property {number[]} id Order id, -1: none.
 */

/**
 * State of charge samples.
 * @typedef {Object} AgvSoc
 * @property {number[]} t
 * @property {number[]} v SOC (%).
 */

/**
 * The AGV's waits for a lock.
 * @typedef {Object} AgvWaits
 * @property {number[]} t
 * @property {number[]} e
 * @property {number[]} n Node it waits at (index).
 * @property {number[]} lock The lock (index into strings).
 * @property {number[]} h The AGV that held it when the wait began, -1: none.
 */

/**
 * AGVs waiting for a charger.
 * @typedef {Object} ChargerWaits
 * @property {number[]} agv
 * @property {number[]} t
 * @property {number[]} e
 * @property {number[]} n Node it waits at (index).
 * @property {number[]} ch The charger (index into places), -1: none.
 */

/**
 * The layout's traffic zones.
 * @typedef {Object} Zones
 * @property {string[]} id
 * @property {string[]} kind mutex, ban or same_direction.
 * @property {string[]} rule
 * @property {string[]} colour
 * @property {number[][]} nodes Nodes inside (indices).
 * @property {number[][]} path A same-direction zone's path in its forward order (indices).
 */

/**
 * Who held or waited for each mutex and same-direction zone.
 * @typedef {Object} ZoneHolds
 * @property {number[]} agv
 * @property {number[]} t
 * @property {number[]} e
 * @property {number[]} z Zone (index).
 * @property {number[]} dir 1 forward, -1 backward, 0 a mutex zone.
 */

/**
 * A segment blocked by an incident.
 * @typedef {Object} Block
 * @property {number} u
 * @property {number} v
 * @property {number} t
 * @property {number} e
 */

/**
 * Deadlocks, errors and other incidents to jump to.
 * @typedef {Object} Incidents
 * @property {number[]} t
 * @property {number[]} agv
 * @property {number[]} kind Index into strings.
 * @property {number[]} code Index into strings.
 * @property {number[]} det Index into strings.
 */

/**
 * Orders delivered in the window and the parts of their lead times (s; -1: none).
 * @typedef {Object} Leads
 * @property {string[]} parts The part keys below, in order.
 * @property {string[]} labels
 * @property {string[]} colours
 * @property {number[]} id
 * @property {number[]} agv
 * @property {number[]} created
 * @property {number[]} lead
 * @property {number[]} wait_assign_s
 * @property {number[]} drive_empty_s
 * @property {number[]} load_s
 * @property {number[]} drive_loaded_s
 * @property {number[]} unload_s
 * @property {number[]} blocked_s
 */

/* ---- end of the payload ---- */

(function () {
  'use strict';
  /** @type {ReplayPayload} */
  var D = JSON.parse(document.getElementById('replay-data').textContent);
  var K = FleetKinematics;
  var M = D.meta, S = D.strings, NODES = D.nodes, SEGS = D.segs, PROF = D.profiles;
  var PLACES = D.places, AGVS = D.agv, ZONES = D.zones, ZH = D.zoneHolds;
  var FROM = M.from_s, TO = M.to_s;
  var violations = [];
  document.addEventListener('securitypolicyviolation', function (e) {
    violations.push(String(e.blockedURI || e.violatedDirective));
  });

  // ---- lookups -------------------------------------------------------------------------------
  var segOf = {};
  for (var i = 0; i < SEGS.u.length; i++) segOf[SEGS.u[i] + ',' + SEGS.v[i]] = i;
  var nodeOf = {};
  for (i = 0; i < NODES.id.length; i++) nodeOf[NODES.id[i]] = i;
  var pieceCache = [];
  var zoneOfLock = {};
  for (i = 0; i < ZONES.id.length; i++) zoneOfLock['zone ' + ZONES.id[i]] = i;

  function piecesOf(p) {
    if (!pieceCache[p]) {
      pieceCache[p] = K.hopPieces(SEGS.len[PROF.seg[p]], PROF.cm[p], PROF.cv[p], PROF.lim[p]);
    }
    return pieceCache[p];
  }

  function upper(arr, x) {  // how many of the sorted `arr` are <= x
    var lo = 0, hi = arr.length;
    while (lo < hi) {
      var mid = (lo + hi) >> 1;
      if (arr[mid] <= x) lo = mid + 1; else hi = mid;
    }
    return lo;
  }

  function hms(t) {
    var neg = t < 0; t = Math.abs(t);
    var h = Math.floor(t / 3600), m = Math.floor(t % 3600 / 60), s = t % 60;
    return (neg ? '-' : '') + h + ':' + (m < 10 ? '0' : '') + m + ':' +
      (s < 10 ? '0' : '') + s.toFixed(1);
  }

  function clock(t) {
    var c = ((M.start_h * 3600 + t) % 86400 + 86400) % 86400;
    var h = Math.floor(c / 3600), m = Math.floor(c % 3600 / 60), s = Math.floor(c % 60);
    return (h < 10 ? '0' : '') + h + ':' + (m < 10 ? '0' : '') + m + ':' + (s < 10 ? '0' : '') + s;
  }

  function duration(s) {
    if (s < 60) return s.toFixed(1) + ' s';
    if (s < 3600) return Math.floor(s / 60) + ' min ' + Math.round(s % 60) + ' s';
    return Math.floor(s / 3600) + ' h ' + Math.round(s % 3600 / 60) + ' min';
  }

  // ---- where each AGV is (twin of fleet_sim.analysis.replay.positions_at) ---------------------
  function rowPosition(P, i, t) {
    var k = P.k[i];
    if (k === 0) {
      var p = P.a[i], s = PROF.seg[p], u = SEGS.u[s], v = SEGS.v[s], len = SEGS.len[s];
      var driven = P.d[i] + Math.min(t, P.e[i]) - P.t[i];
      var along = K.distanceAt(piecesOf(p), PROF.vin[p], PROF.vout[p], PROF.acc[p], PROF.dec[p],
                               driven);
      if (along >= len) {
        return {x: NODES.x[v], y: NODES.y[v], where: 'track', node: v, to: -1, along: 0, seg: s};
      }
      var f = along / len;
      return {x: NODES.x[u] + (NODES.x[v] - NODES.x[u]) * f,
              y: NODES.y[u] + (NODES.y[v] - NODES.y[u]) * f,
              where: 'track', node: u, to: v, along: along, seg: s};
    }
    if (k === 3) {
      if (i === 0) {
        var n0 = P.a[i];
        return {x: NODES.x[n0], y: NODES.y[n0], where: 'off', node: n0, to: -1, along: 0, seg: -1};
      }
      var before = rowPosition(P, i - 1, P.t[i]);
      return {x: before.x, y: before.y, where: 'off', node: before.node, to: before.to,
              along: before.along, seg: before.seg};
    }
    var n = P.a[i];
    return {x: NODES.x[n], y: NODES.y[n], where: k === 1 ? 'track' : 'parking', node: n, to: -1,
            along: 0, seg: -1};
  }

  function positionOf(a, t) {
    var P = AGVS[a].p;
    var i = upper(P.t, t) - 1;
    return i < 0 ? null : rowPosition(P, i, t);
  }

  function positionsAt(t) {
    var out = {};
    for (var a = 0; a < AGVS.length; a++) {
      var p = positionOf(a, t);
      if (p === null) continue;
      out[AGVS[a].id] = {x: p.x, y: p.y, where: p.where, node: NODES.id[p.node],
                         to_node: p.to >= 0 ? NODES.id[p.to] : '', along_m: p.along};
    }
    return out;
  }

  // ---- what each AGV is doing --------------------------------------------------------------------
  function spellAt(a, t) {
    var s = AGVS[a].s;
    var i = upper(s.t, t) - 1;
    return i >= 0 && t <= s.e[i] ? i : -1;
  }

  function orderAt(a, t) {
    var o = AGVS[a].o;
    var i = upper(o.t, t) - 1;
    return i >= 0 ? o.id[i] : -1;
  }

  function socAt(a, t) {
    var b = AGVS[a].b;
    var i = upper(b.t, t) - 1;
    return i >= 0 ? {v: b.v[i], t: b.t[i]} : null;
  }

  function waitAt(a, t) {
    var w = AGVS[a].w;
    var i = upper(w.t, t) - 1;
    return i >= 0 && t < w.e[i] ? i : -1;
  }

  function zonesAt(t) {  // who holds each traffic zone, which way, and who waits for it
    var out = [];
    for (var z = 0; z < ZONES.id.length; z++) {
      out.push({id: ZONES.id[z], kind: ZONES.kind[z], holders: [], dir: 0, waiting: []});
    }
    for (var i = 0; i < ZH.agv.length; i++) {
      if (ZH.t[i] <= t && t < ZH.e[i]) {
        var zone = out[ZH.z[i]];
        zone.holders.push(ZH.agv[i]);
        if (ZH.dir[i]) zone.dir = ZH.dir[i];
      }
    }
    for (var a = 0; a < AGVS.length; a++) {
      var wi = waitAt(a, t);
      if (wi < 0) continue;
      var lock = S[AGVS[a].w.lock[wi]];
      if (lock in zoneOfLock) out[zoneOfLock[lock]].waiting.push(AGVS[a].id);
    }
    out.forEach(function (zone) {
      zone.holders.sort(function (x, y) { return x - y; });
      zone.waiting.sort(function (x, y) { return x - y; });
    });
    return out;
  }

  function chargerWaitsAt(t) {
    var c = D.chargerWaits, out = [];
    for (var i = 0; i < c.agv.length; i++) if (c.t[i] <= t && t < c.e[i]) out.push(i);
    return out;
  }

  // ---- the floor ----------------------------------------------------------------------------------
  var floor = document.getElementById('floor');
  var fctx = floor.getContext('2d');
  var base = document.createElement('canvas');
  var view = {scale: 1, ox: 0, oy: 0};
  var dpr = window.devicePixelRatio || 1;
  var now = FROM, playing = false, lastFrame = 0;
  var selected = null;
  var drawn = [];
  var heat = {on: false, from: FROM, to: TO, perNode: null, max: 0};
  var overlays = {charger: true, blocked: true, zones: true};
  var drawnZones = [];

  function sx(x) { return view.ox + x * view.scale; }
  function sy(y) { return view.oy - y * view.scale; }

  function fit() {
    var w = floor.clientWidth, h = floor.clientHeight;
    var minX = Math.min.apply(null, NODES.x), maxX = Math.max.apply(null, NODES.x);
    var minY = Math.min.apply(null, NODES.y), maxY = Math.max.apply(null, NODES.y);
    var pad = ZONES.id.length ? 48 : 30;  // room for the zones' outlines and labels
    view.scale = Math.min((w - 2 * pad) / Math.max(maxX - minX, 1),
                          (h - 2 * pad) / Math.max(maxY - minY, 1));
    view.ox = (w - (maxX - minX) * view.scale) / 2 - minX * view.scale;
    view.oy = (h + (maxY - minY) * view.scale) / 2 + minY * view.scale;
  }

  function resize() {
    dpr = window.devicePixelRatio || 1;
    var w = floor.clientWidth, h = floor.clientHeight;
    floor.width = Math.round(w * dpr); floor.height = Math.round(h * dpr);
    base.width = floor.width; base.height = floor.height;
  }

  function agvRadius(a) {
    return Math.max(3.5, Math.min(14, AGVS[a].length_m / 2 * view.scale));
  }

  function zoneBox(z) {  // screen rectangle round a zone's nodes, with a margin
    var pad = Math.max(6, Math.min(14, 0.8 * view.scale)), nodes = ZONES.nodes[z];
    var xs = nodes.map(function (n) { return sx(NODES.x[n]); });
    var ys = nodes.map(function (n) { return sy(NODES.y[n]); });
    var x0 = Math.min.apply(null, xs) - pad, y0 = Math.min.apply(null, ys) - pad;
    return {x: x0, y: y0, w: Math.max.apply(null, xs) + pad - x0,
            h: Math.max.apply(null, ys) + pad - y0};
  }

  function pathLine(c, path) {
    c.beginPath();
    path.forEach(function (n, k) {
      if (k === 0) c.moveTo(sx(NODES.x[n]), sy(NODES.y[n]));
      else c.lineTo(sx(NODES.x[n]), sy(NODES.y[n]));
    });
    c.stroke();
  }

  function arrowAlong(c, path, way, colour, width) {  // an arrow over the aisle, its way
    var a = way > 0 ? path[0] : path[path.length - 1], b = way > 0 ? path[path.length - 1] : path[0];
    var x0 = sx(NODES.x[a]), y0 = sy(NODES.y[a]), x1 = sx(NODES.x[b]), y1 = sy(NODES.y[b]);
    var ang = Math.atan2(y1 - y0, x1 - x0), len = Math.hypot(x1 - x0, y1 - y0);
    var head = Math.max(7, Math.min(16, len / 6));
    var mx = (x0 + x1) / 2 + Math.cos(ang) * len / 4, my = (y0 + y1) / 2 + Math.sin(ang) * len / 4;
    c.strokeStyle = colour; c.fillStyle = colour; c.lineWidth = width;
    c.beginPath(); c.moveTo(x0 + (x1 - x0) * 0.15, y0 + (y1 - y0) * 0.15); c.lineTo(mx, my); c.stroke();
    c.beginPath(); c.moveTo(mx + Math.cos(ang) * head, my + Math.sin(ang) * head);
    c.lineTo(mx + Math.cos(ang + 2.5) * head, my + Math.sin(ang + 2.5) * head);
    c.lineTo(mx + Math.cos(ang - 2.5) * head, my + Math.sin(ang - 2.5) * head);
    c.fill();
  }

  function aisleFrame(z) {  // where a same-direction zone's texts go: along its aisle
    var path = ZONES.path[z], a = path[0], b = path[path.length - 1];
    var x0 = sx(NODES.x[a]), y0 = sy(NODES.y[a]), x1 = sx(NODES.x[b]), y1 = sy(NODES.y[b]);
    var ang = Math.atan2(y1 - y0, x1 - x0);  // read left to right, or upwards
    if (ang >= Math.PI / 2) ang -= Math.PI; else if (ang < -Math.PI / 2) ang += Math.PI;
    return {x0: x0, y0: y0, x1: x1, y1: y1, ang: ang,
            half: Math.max(10, Math.min(26, 1.6 * view.scale)) / 2};
  }

  function along(f, share, dx, dy) {  // a point `share` of the way along an aisle, moved by
    var x = f.x0 + (f.x1 - f.x0) * share, y = f.y0 + (f.y1 - f.y0) * share;  // (dx, dy) in
    return {x: x + dx * Math.cos(f.ang) - dy * Math.sin(f.ang),            // the turned frame
            y: y + dx * Math.sin(f.ang) + dy * Math.cos(f.ang)};
  }

  function turnedText(c, at, ang, draw) {
    c.save(); c.translate(at.x, at.y); c.rotate(ang); draw(); c.restore();
  }

  function drawZones(c) {  // under the track: outlines, aisle bands, ids and rules
    drawnZones = [];
    for (var z = 0; z < ZONES.id.length; z++) {
      var colour = ZONES.colour[z], label = ZONES.id[z] + ' (' + ZONES.rule[z] + ')', lx, ly, box;
      c.save();
      if (ZONES.kind[z] === 'same_direction') {
        var path = ZONES.path[z];
        c.lineCap = 'round'; c.lineJoin = 'round';
        c.globalAlpha = 0.28; c.strokeStyle = colour;
        c.lineWidth = Math.max(10, Math.min(26, 1.6 * view.scale));
        pathLine(c, path);
        c.globalAlpha = 0.55;
        arrowAlong(c, path, 1, colour, 1.5);
      } else {
        box = zoneBox(z);
        c.globalAlpha = 0.1; c.fillStyle = colour; c.fillRect(box.x, box.y, box.w, box.h);
        c.globalAlpha = 0.9; c.strokeStyle = colour; c.lineWidth = 1.3; c.setLineDash([5, 4]);
        c.strokeRect(box.x, box.y, box.w, box.h);
        lx = box.x + 2; ly = box.y - 4;
      }
      c.restore();
      c.fillStyle = colour; c.font = 'bold 10px system-ui, sans-serif';
      var width = c.measureText(label).width;
      if (ZONES.kind[z] === 'same_direction') {  // along the aisle, beside its band
        var f = aisleFrame(z);
        turnedText(c, along(f, 0.5, 0, 0), f.ang, function () {
          c.fillText(label, -width / 2, -f.half - 3);
        });
      } else {
        lx = Math.max(2, Math.min(lx, floor.clientWidth - width - 4));
        c.fillText(label, lx, ly);
      }
      box = zoneBox(z);  // where it is on the screen (for tests)
      drawnZones.push({id: ZONES.id[z], kind: ZONES.kind[z], colour: colour, lx: lx, ly: ly,
                       x: box.x, y: box.y, w: box.w, h: box.h});
    }
  }

  function drawZonesNow(c, t) {  // live: holders (and their way), waiters, as a badge
    c.font = 'bold 11px system-ui, sans-serif';
    zonesAt(t).forEach(function (zone, z) {
      if (ZONES.kind[z] === 'ban' || !(zone.holders.length || zone.waiting.length)) return;
      var colour = ZONES.colour[z], d = drawnZones[z];
      if (ZONES.kind[z] === 'same_direction' && zone.dir) {
        c.save(); c.globalAlpha = 0.95; arrowAlong(c, ZONES.path[z], zone.dir, colour, 3); c.restore();
      }
      if (zone.waiting.length) {
        c.save(); c.strokeStyle = '#f29900'; c.lineWidth = 2.5; c.setLineDash([4, 3]);
        if (ZONES.kind[z] === 'same_direction') {
          c.lineWidth = Math.max(12, Math.min(28, 1.8 * view.scale)); c.globalAlpha = 0.35;
          pathLine(c, ZONES.path[z]);
        } else {
          var box = zoneBox(z); c.strokeRect(box.x, box.y, box.w, box.h);
        }
        c.restore();
      }
      var text = zone.holders.length + ' in' +
        (zone.dir ? (zone.dir > 0 ? ' forward' : ' backward') : '') +
        (zone.waiting.length ? ', ' + zone.waiting.length + ' waiting' : '');
      var w = c.measureText(text).width + 8, inside;  // a point of the badge, not its text
      var badge = function (x, y) {
        c.fillStyle = colour; c.fillRect(x, y, w, 14);
        c.fillStyle = '#ffffff'; c.fillText(text, x + 4, y + 11);
      };
      if (ZONES.kind[z] === 'same_direction') {  // along the aisle, the other side of it
        var f = aisleFrame(z), at = along(f, 0.3, 0, 0);
        turnedText(c, at, f.ang, function () { badge(-w / 2, f.half + 2); });
        inside = along(f, 0.3, -w / 2 + 2, f.half + 9);
      } else {
        var x = Math.max(2, Math.min(d.lx, floor.clientWidth - w - 2)), y = d.ly + 4;
        badge(x, y);
        inside = {x: x + 2, y: y + 7};
      }
      d.bx = inside.x; d.by = inside.y;
    });
  }

  function drawBase() {
    var c = base.getContext('2d');
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    c.clearRect(0, 0, base.width, base.height);
    if (overlays.zones) drawZones(c);
    c.lineCap = 'round';
    for (var i = 0; i < SEGS.u.length; i++) {
      var u = SEGS.u[i], v = SEGS.v[i];
      if (SEGS.twoWay[i] && u > v) continue;  // a two-way segment once
      c.strokeStyle = SEGS.twoWay[i] ? '#9aa0a6' : '#bdc1c6';
      c.lineWidth = Math.max(1.5, Math.min(4, 0.25 * view.scale));
      c.beginPath(); c.moveTo(sx(NODES.x[u]), sy(NODES.y[u]));
      c.lineTo(sx(NODES.x[v]), sy(NODES.y[v])); c.stroke();
      if (!SEGS.twoWay[i] && view.scale > 5) {  // one-way: a chevron pointing along
        var mx = (sx(NODES.x[u]) + sx(NODES.x[v])) / 2, my = (sy(NODES.y[u]) + sy(NODES.y[v])) / 2;
        var ang = Math.atan2(sy(NODES.y[v]) - sy(NODES.y[u]), sx(NODES.x[v]) - sx(NODES.x[u]));
        c.strokeStyle = '#80868b'; c.lineWidth = 1;
        c.beginPath();
        c.moveTo(mx - 4 * Math.cos(ang - 0.6), my - 4 * Math.sin(ang - 0.6));
        c.lineTo(mx, my);
        c.lineTo(mx - 4 * Math.cos(ang + 0.6), my - 4 * Math.sin(ang + 0.6));
        c.stroke();
      }
    }
    for (i = 0; i < NODES.id.length; i++) {
      var place = NODES.place[i] >= 0;
      c.fillStyle = NODES.colour[i];
      c.beginPath();
      c.arc(sx(NODES.x[i]), sy(NODES.y[i]), place ? 4.5 : 1.8, 0, 2 * Math.PI);
      c.fill();
      if (place && view.scale > 7) {
        c.fillStyle = '#5f6368'; c.font = '10px system-ui, sans-serif';
        c.fillText(PLACES.id[NODES.place[i]], sx(NODES.x[i]) + 6, sy(NODES.y[i]) + 12);
      }
    }
    if (heat.on && heat.perNode) {
      for (i = 0; i < NODES.id.length; i++) {
        var value = heat.perNode[i];
        if (!(value > 0)) continue;
        var share = value / heat.max;
        c.fillStyle = heatColour(share);
        c.globalAlpha = 0.75;
        c.beginPath();
        c.arc(sx(NODES.x[i]), sy(NODES.y[i]), 3 + 10 * Math.sqrt(share), 0, 2 * Math.PI);
        c.fill();
        c.globalAlpha = 1;
      }
    }
  }

  function heatColour(share) {  // pale yellow to red
    var r = Math.round(253 + (217 - 253) * share), g = Math.round(226 + (48 - 226) * share),
      b = Math.round(147 + (37 - 147) * share);
    return 'rgb(' + r + ',' + g + ',' + b + ')';
  }

  function computeHeat() {
    var per = new Array(NODES.id.length).fill(0);
    for (var a = 0; a < AGVS.length; a++) {
      var w = AGVS[a].w;
      for (var i = 0; i < w.t.length; i++) {
        var lo = Math.max(w.t[i], heat.from), hi = Math.min(w.e[i], heat.to);
        if (hi > lo) per[w.n[i]] += hi - lo;
      }
    }
    var hours = Math.max((heat.to - heat.from) / 3600, 1e-9), max = 0;
    for (i = 0; i < per.length; i++) { per[i] /= hours; if (per[i] > max) max = per[i]; }
    heat.perNode = per; heat.max = max;
    var top = per.indexOf(max);
    document.getElementById('heat-note').textContent = max > 0
      ? 'most waiting: ' + NODES.id[top] + ', ' + max.toFixed(0) + ' s per hour'
      : 'no AGV waited in this window';
  }

  function segmentLine(c, s) {
    var u = SEGS.u[s], v = SEGS.v[s];
    c.beginPath(); c.moveTo(sx(NODES.x[u]), sy(NODES.y[u]));
    c.lineTo(sx(NODES.x[v]), sy(NODES.y[v])); c.stroke();
  }

  function drawFrame() {
    var c = fctx;
    c.setTransform(1, 0, 0, 1, 0, 0);
    c.clearRect(0, 0, floor.width, floor.height);
    c.drawImage(base, 0, 0);
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    var t = now;
    if (overlays.blocked) {
      c.save();
      c.lineWidth = 5; c.strokeStyle = '#d93025'; c.setLineDash([6, 4]);
      for (var b = 0; b < D.blocks.length; b++) {
        var blk = D.blocks[b];
        if (blk.t <= t && t < blk.e) {
          c.beginPath(); c.moveTo(sx(NODES.x[blk.u]), sy(NODES.y[blk.u]));
          c.lineTo(sx(NODES.x[blk.v]), sy(NODES.y[blk.v])); c.stroke();
        }
      }
      c.setLineDash([]); c.strokeStyle = '#f29900'; c.lineWidth = 4; c.globalAlpha = 0.8;
      for (var a = 0; a < AGVS.length; a++) {
        var wi = waitAt(a, t);
        if (wi < 0) continue;
        var w = AGVS[a].w, lock = S[w.lock[wi]], from = w.n[wi];
        if (lock in D.corridors) {
          D.corridors[lock].forEach(function (s) { segmentLine(c, s); });
        } else if (lock in nodeOf && (from + ',' + nodeOf[lock]) in segOf) {
          segmentLine(c, segOf[from + ',' + nodeOf[lock]]);
        }
      }
      c.restore();
    }
    if (overlays.zones) drawZonesNow(c, t);
    drawn = [];
    var parked = {};
    for (a = 0; a < AGVS.length; a++) {
      var p = positionOf(a, t);
      if (p === null) continue;
      var r = agvRadius(a);
      var x = sx(p.x), y = sy(p.y);
      if (p.where === 'parking') {  // side by side beside the parking node
        var slot = parked[p.node] = (parked[p.node] || 0) + 1;
        var cols = 5, col = (slot - 1) % cols, row = Math.floor((slot - 1) / cols);
        x += (col + 1) * (2 * r + 2); y -= (row + 1) * (2 * r + 2);
      }
      var si = spellAt(a, t), spells = AGVS[a].s;
      var state = si >= 0 ? spells.st[si] : 0, loaded = si >= 0 && spells.l[si] === 1;
      var colour = D.stateColours[state];
      c.save();
      if (p.where === 'off') c.globalAlpha = 0.45;
      if (p.seg >= 0 && p.where === 'track') {  // nose: the way it faces
        var s0 = SEGS.u[p.seg], s1 = SEGS.v[p.seg];
        var ang = Math.atan2(sy(NODES.y[s1]) - sy(NODES.y[s0]), sx(NODES.x[s1]) - sx(NODES.x[s0]));
        c.fillStyle = '#202124';
        c.beginPath();
        c.moveTo(x + (r + 4) * Math.cos(ang), y + (r + 4) * Math.sin(ang));
        c.lineTo(x + r * Math.cos(ang + 0.5), y + r * Math.sin(ang + 0.5));
        c.lineTo(x + r * Math.cos(ang - 0.5), y + r * Math.sin(ang - 0.5));
        c.fill();
      }
      c.fillStyle = colour;
      c.beginPath(); c.arc(x, y, r, 0, 2 * Math.PI); c.fill();
      c.lineWidth = 1; c.strokeStyle = '#202124';
      if (p.where === 'off') c.setLineDash([3, 2]);
      c.stroke();
      c.setLineDash([]);
      if (loaded) {
        var q = r * 0.45;
        c.fillStyle = '#202124'; c.fillRect(x - q, y - q, 2 * q, 2 * q);
      }
      c.restore();
      if (selected && selected.type === 'agv' && selected.a === a) {
        c.strokeStyle = '#a142f4'; c.lineWidth = 2.5;
        c.beginPath(); c.arc(x, y, r + 5, 0, 2 * Math.PI); c.stroke();
      }
      if (overlays.blocked && waitAt(a, t) >= 0) {
        c.strokeStyle = '#f29900'; c.lineWidth = 2;
        c.beginPath(); c.arc(x, y, r + 2.5, 0, 2 * Math.PI); c.stroke();
      }
      if (r >= 5) {
        c.fillStyle = '#202124'; c.font = '10px system-ui, sans-serif';
        c.fillText(String(AGVS[a].id), x + r + 2, y - r);
      }
      drawn.push({agv: AGVS[a].id, x: (x - view.ox) / view.scale, y: (view.oy - y) / view.scale,
                  where: p.where, sx: x, sy: y, r: r, colour: colour, loaded: loaded});
    }
    if (selected && selected.type === 'node') {
      var n = selected.n;
      c.strokeStyle = '#a142f4'; c.lineWidth = 2.5;
      c.beginPath(); c.arc(sx(NODES.x[n]), sy(NODES.y[n]), 8, 0, 2 * Math.PI); c.stroke();
    }
    if (overlays.charger) drawChargerBadges(c, t);
  }

  function drawChargerBadges(c, t) {
    var waiting = chargerWaitsAt(t);
    if (!waiting.length) return;
    var byNode = {};
    waiting.forEach(function (i) {
      var ch = D.chargerWaits.ch[i];
      var node = ch >= 0 ? PLACES.node[ch] : -1;
      byNode[node] = (byNode[node] || 0) + 1;
    });
    c.font = 'bold 11px system-ui, sans-serif';
    Object.keys(byNode).forEach(function (key) {
      var node = Number(key), label = byNode[key] + ' queued';
      var x = node >= 0 ? sx(NODES.x[node]) : 10, y = node >= 0 ? sy(NODES.y[node]) - 12 : 16;
      if (node < 0) label = byNode[key] + ' waiting for a charger';
      var w = c.measureText(label).width + 8;
      c.fillStyle = '#f9ab00'; c.fillRect(x - w / 2, y - 10, w, 14);
      c.fillStyle = '#202124'; c.fillText(label, x - w / 2 + 4, y + 1);
    });
  }

  // ---- the side panel ----------------------------------------------------------------------------
  var info = document.getElementById('info');
  var chargersBox = document.getElementById('chargers');
  var zonesBox = document.getElementById('zones');

  function describeAgv(a, t) {
    var lines = [], id = AGVS[a].id, si = spellAt(a, t), sp = AGVS[a].s;
    if (si >= 0) {
      lines.push('AGV ' + id + '  ' + D.states[sp.st[si]] + ' since ' + hms(sp.t[si]) + ' (' +
                 duration(t - sp.t[si]) + ')');
      var why = S[sp.ev[si]] + (S[sp.det[si]] ? ': ' + S[sp.det[si]] : '');
      lines.push('why    ' + why);
      lines.push('load   ' + (sp.l[si] ? 'loaded' : 'empty'));
    } else {
      lines.push('AGV ' + id);
    }
    var order = orderAt(a, t);
    lines.push('order  ' + (order >= 0 ? String(order) : 'none'));
    var soc = socAt(a, t);
    lines.push('SOC    ' + (soc ? soc.v.toFixed(1) + ' % (at ' + hms(soc.t) + ')' : 'n/a'));
    var p = positionOf(a, t);
    if (p) {
      if (p.where === 'parking') lines.push('where  in parking by ' + NODES.id[p.node]);
      else if (p.where === 'off') lines.push('where  taken off the track near ' + NODES.id[p.node]);
      else if (p.to >= 0) {
        lines.push('where  ' + NODES.id[p.node] + ' -> ' + NODES.id[p.to] + ', ' +
                   p.along.toFixed(1) + ' m along');
      } else lines.push('where  at ' + NODES.id[p.node]);
    }
    var wi = waitAt(a, t);
    if (wi >= 0) {
      var w = AGVS[a].w;
      lines.push('wait   for ' + S[w.lock[wi]] + (w.h[wi] >= 0 ? ' (held by AGV ' + w.h[wi] + ')' : '') +
                 ' since ' + hms(w.t[wi]));
    }
    chargerWaitsAt(t).forEach(function (i) {
      if (D.chargerWaits.agv[i] === id) {
        lines.push('charge waiting for a charger since ' + hms(D.chargerWaits.t[i]));
      }
    });
    return lines.join('\n');
  }

  function describeNode(n, t) {
    var lines = ['node ' + NODES.id[n] + ' (' + NODES.kind[n] + ')'];
    if (NODES.place[n] >= 0) {
      lines.push('place  ' + PLACES.id[NODES.place[n]] + ' (' + PLACES.kind[NODES.place[n]] + ')');
    }
    var here = [], waiting = [];
    for (var a = 0; a < AGVS.length; a++) {
      var p = positionOf(a, t);
      if (p && p.node === n && p.to < 0) here.push(AGVS[a].id + (p.where !== 'track' ? ' (' + p.where + ')' : ''));
      var wi = waitAt(a, t);
      if (wi >= 0 && S[AGVS[a].w.lock[wi]] === NODES.id[n]) {
        waiting.push(AGVS[a].id + ' since ' + hms(AGVS[a].w.t[wi]));
      }
    }
    lines.push('AGVs   ' + (here.length ? here.join(', ') : 'none'));
    lines.push('wait for it  ' + (waiting.length ? 'AGV ' + waiting.join(', AGV ') : 'nobody'));
    if (heat.perNode) {
      lines.push('waiting here ' + heat.perNode[n].toFixed(1) + ' s/h (heat window)');
    }
    return lines.join('\n');
  }

  function describeZones(t) {
    return zonesAt(t).map(function (zone, z) {
      var line = zone.id + ' (' + ZONES.rule[z] + ')';
      if (zone.kind === 'ban') return line;
      line += ': ' + (zone.holders.length ? 'AGV ' + zone.holders.join(', ') +
        (zone.dir ? (zone.dir > 0 ? ' forward' : ' backward') : '') : 'empty');
      if (zone.waiting.length) line += '; waiting AGV ' + zone.waiting.join(', ');
      return line;
    }).join('\n');
  }

  function updatePanel() {
    var t = now;
    if (selected && selected.type === 'agv') info.textContent = describeAgv(selected.a, t);
    else if (selected && selected.type === 'node') info.textContent = describeNode(selected.n, t);
    if (zonesBox) zonesBox.textContent = overlays.zones ? describeZones(t) : '';
    if (!overlays.charger) { chargersBox.textContent = ''; return; }
    var lines = [];
    for (var i = 0; i < PLACES.id.length; i++) {
      if (PLACES.kind[i] !== 'charger') continue;
      var node = PLACES.node[i], at = [];
      for (var a = 0; a < AGVS.length; a++) {
        var si = spellAt(a, t), p;
        if (si >= 0 && D.states[AGVS[a].s.st[si]] === 'Charging' && (p = positionOf(a, t)) &&
            p.node === node && p.to < 0) at.push('AGV ' + AGVS[a].id);
      }
      lines.push(PLACES.id[i] + ': ' + (at.length ? 'charging ' + at.join(', ') : 'free'));
    }
    var queue = chargerWaitsAt(t).map(function (j) {
      return 'AGV ' + D.chargerWaits.agv[j] + ' (' + duration(t - D.chargerWaits.t[j]) + ')';
    });
    lines.push('queue: ' + (queue.length ? queue.join(', ') : 'none'));
    chargersBox.textContent = lines.join('\n');
    chargersBox.style.whiteSpace = 'pre-wrap';
  }

  // ---- time -------------------------------------------------------------------------------------
  var slider = document.getElementById('slider');
  var clockBox = document.getElementById('clock');
  var playButton = document.getElementById('play');
  var speedBox = document.getElementById('speed');
  slider.min = FROM; slider.max = TO; slider.value = FROM;

  function render() {
    drawFrame();
    updatePanel();
    clockBox.textContent = 't ' + hms(now) + '  (clock ' + clock(now) + ')';
    slider.value = now;
    drawGanttCursor();
  }

  function seek(t) {
    now = Math.min(Math.max(Number(t), FROM), TO);
    render();
    return now;
  }

  function frame(ms) {
    if (!playing) return;
    if (lastFrame) now += (ms - lastFrame) / 1000 * Number(speedBox.value);
    lastFrame = ms;
    if (now >= TO) { now = TO; setPlaying(false); }
    render();
    if (playing) window.requestAnimationFrame(frame);
  }

  function remember() {  // the moment in the address, to send to a colleague
    var hash = '#t=' + now.toFixed(1);
    if (selected && selected.type === 'agv') hash += '&agv=' + AGVS[selected.a].id;
    if (selected && selected.type === 'node') hash += '&node=' + encodeURIComponent(NODES.id[selected.n]);
    if (heat.on) hash += '&heat=1';
    try { window.history.replaceState(null, '', hash); } catch (e) { /* not where it is stored */ }
  }

  function setPlaying(on) {
    if (playing && !on) remember();
    playing = on;
    playButton.textContent = on ? '\u23F8 pause' : '\u25B6 play';
    lastFrame = 0;
    if (on) {
      if (now >= TO) now = FROM;
      window.requestAnimationFrame(frame);
    }
  }

  playButton.addEventListener('click', function () { setPlaying(!playing); });
  slider.addEventListener('input', function () { seek(slider.value); });
  slider.addEventListener('change', remember);
  document.addEventListener('keydown', function (e) {
    if (e.key === ' ' && e.target.tagName !== 'INPUT' && e.target.tagName !== 'SELECT') {
      e.preventDefault(); setPlaying(!playing);
    }
  });

  // ---- jumps to deadlocks and errors --------------------------------------------------------------
  var INC = D.incidents, jumpBox = document.getElementById('jumpkind');
  (function () {
    var kinds = [['deadlock', 'deadlock'], ['error', 'error (any code)']];
    var codes = {};
    for (var i = 0; i < INC.t.length; i++) if (S[INC.code[i]]) codes[S[INC.code[i]]] = true;
    Object.keys(codes).sort().forEach(function (code) { kinds.push(['code:' + code, code]); });
    kinds.forEach(function (k) {
      var count = 0;
      for (var j = 0; j < INC.t.length; j++) if (matches(j, k[0])) count++;
      var option = document.createElement('option');
      option.value = k[0]; option.textContent = k[1] + ' (' + count + ')';
      jumpBox.appendChild(option);
    });
  })();

  function matches(i, kind) {
    if (kind.indexOf('code:') === 0) return S[INC.code[i]] === kind.slice(5);
    return S[INC.kind[i]] === kind;
  }

  function jump(direction) {
    var kind = jumpBox.value, best = -1;
    for (var i = 0; i < INC.t.length; i++) {
      if (!matches(i, kind)) continue;
      if (direction > 0 && INC.t[i] > now + 0.05) { best = i; break; }
      if (direction < 0 && INC.t[i] < now - 0.05) best = i;
    }
    if (best < 0) { clockBox.textContent += '  (no ' + (direction > 0 ? 'later' : 'earlier') + ' one)'; return; }
    setPlaying(false);
    for (var a = 0; a < AGVS.length; a++) if (AGVS[a].id === INC.agv[best]) selected = {type: 'agv', a: a};
    seek(INC.t[best]);
    info.textContent += '\n\n' + S[INC.det[best]];
  }
  document.getElementById('next').addEventListener('click', function () { jump(1); });
  document.getElementById('prev').addEventListener('click', function () { jump(-1); });

  // ---- pointer on the floor ---------------------------------------------------------------------
  var drag = null;
  floor.addEventListener('mousedown', function (e) {
    drag = {x: e.offsetX, y: e.offsetY, ox: view.ox, oy: view.oy, moved: false};
  });
  window.addEventListener('mouseup', function (e) {
    if (drag && !drag.moved && e.target === floor) pick(e.offsetX, e.offsetY);
    drag = null;
  });
  floor.addEventListener('mousemove', function (e) {
    if (!drag) return;
    var dx = e.offsetX - drag.x, dy = e.offsetY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
    if (drag.moved) { view.ox = drag.ox + dx; view.oy = drag.oy + dy; drawBase(); render(); }
  });
  floor.addEventListener('wheel', function (e) {
    e.preventDefault();
    var k = Math.exp(-e.deltaY * 0.0015);
    view.ox = e.offsetX - (e.offsetX - view.ox) * k;
    view.oy = e.offsetY - (e.offsetY - view.oy) * k;
    view.scale *= k;
    drawBase(); render();
  }, {passive: false});
  floor.addEventListener('dblclick', function () { fit(); drawBase(); render(); });

  function pick(x, y) {
    var best = null, bestD = 1e9;
    drawn.forEach(function (d, i) {
      var dd = Math.hypot(d.sx - x, d.sy - y);
      if (dd <= d.r + 4 && dd < bestD) { bestD = dd; best = i; }
    });
    if (best !== null) {
      for (var a = 0; a < AGVS.length; a++) {
        if (AGVS[a].id === drawn[best].agv) selected = {type: 'agv', a: a};
      }
    } else {
      var n = -1;
      bestD = 9;
      for (var i = 0; i < NODES.id.length; i++) {
        var dn = Math.hypot(sx(NODES.x[i]) - x, sy(NODES.y[i]) - y);
        if (dn < bestD) { bestD = dn; n = i; }
      }
      selected = n >= 0 ? {type: 'node', n: n} : null;
      if (!selected) info.textContent = 'Click an AGV or a node.';
    }
    render();
    if (!playing) remember();
  }

  // ---- overlays ---------------------------------------------------------------------------------
  var heatFrom = document.getElementById('heat-from'), heatTo = document.getElementById('heat-to');
  heatFrom.value = (FROM / 3600).toFixed(2); heatTo.value = (TO / 3600).toFixed(2);

  function heatWindow() {
    var lo = Number(heatFrom.value) * 3600, hi = Number(heatTo.value) * 3600;
    if (!isFinite(lo) || !isFinite(hi) || lo >= hi) {
      document.getElementById('heat-note').textContent = 'window: two hours, the first smaller';
      return;
    }
    heat.from = Math.max(lo, FROM); heat.to = Math.min(hi, TO);
    computeHeat(); drawBase(); render();
  }
  document.getElementById('ov-heat').addEventListener('change', function (e) {
    heat.on = e.target.checked; if (heat.on) heatWindow(); else { drawBase(); render(); }
  });
  heatFrom.addEventListener('change', heatWindow);
  heatTo.addEventListener('change', heatWindow);
  document.getElementById('ov-charger').addEventListener('change', function (e) {
    overlays.charger = e.target.checked; render();
  });
  document.getElementById('ov-blocked').addEventListener('change', function (e) {
    overlays.blocked = e.target.checked; render();
  });
  if (ZONES.id.length) {
    document.getElementById('ov-zones').addEventListener('change', function (e) {
      overlays.zones = e.target.checked; drawBase(); render();
    });
  }
  (function legend() {
    var box = document.getElementById('legend');
    D.states.forEach(function (name, i) {
      var item = document.createElement('span'), sw = document.createElement('span');
      sw.className = 'sw'; sw.style.background = D.stateColours[i];
      item.appendChild(sw); item.appendChild(document.createTextNode(name));
      box.appendChild(item);
    });
  })();

  // ---- the timeline (Gantt) ---------------------------------------------------------------------
  var gantt = document.getElementById('gantt'), gctx = gantt.getContext('2d');
  var gbase = document.createElement('canvas');
  var tip = document.getElementById('tip');
  var G = {label: 56, top: 20, row: Math.max(5, Math.min(14, Math.floor(640 / Math.max(AGVS.length, 1)))),
           v0: FROM, v1: TO, w: 0, h: 0};

  function gx(t) { return G.label + (t - G.v0) / (G.v1 - G.v0) * (G.w - G.label - 6); }
  function gt(x) { return G.v0 + (x - G.label) / (G.w - G.label - 6) * (G.v1 - G.v0); }

  function sizeGantt() {
    G.w = gantt.clientWidth || 800;
    G.h = G.top + G.row * AGVS.length + 4;
    gantt.style.height = G.h + 'px';
    gantt.width = Math.round(G.w * dpr); gantt.height = Math.round(G.h * dpr);
    gbase.width = gantt.width; gbase.height = gantt.height;
  }

  function tickStep(span) {
    var steps = [1, 2, 5, 10, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 14400];
    for (var i = 0; i < steps.length; i++) if (span / steps[i] <= 10) return steps[i];
    return 28800;
  }

  function drawGanttBase() {
    var c = gbase.getContext('2d');
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    c.clearRect(0, 0, G.w, G.h);
    c.font = '10px system-ui, sans-serif';
    var step = tickStep(G.v1 - G.v0);
    c.strokeStyle = '#e8eaed'; c.fillStyle = '#5f6368'; c.lineWidth = 1;
    for (var t = Math.ceil(G.v0 / step) * step; t <= G.v1; t += step) {
      var x = Math.round(gx(t)) + 0.5;
      c.beginPath(); c.moveTo(x, G.top - 4); c.lineTo(x, G.h); c.stroke();
      c.fillText(hms(t).replace(/\.0$/, ''), x + 2, 11);
    }
    for (var a = 0; a < AGVS.length; a++) {
      var y = G.top + a * G.row, s = AGVS[a].s;
      c.fillStyle = '#5f6368';
      if (G.row >= 8) c.fillText('AGV ' + AGVS[a].id, 2, y + G.row - 2);
      var i0 = Math.max(upper(s.t, G.v0) - 1, 0);
      for (var i = i0; i < s.t.length && s.t[i] <= G.v1; i++) {
        var x0 = gx(Math.max(s.t[i], G.v0)), x1 = gx(Math.min(s.e[i], G.v1));
        c.fillStyle = D.stateColours[s.st[i]];
        c.fillRect(x0, y + 1, Math.max(x1 - x0, 0.6), G.row - 2);
        if (s.l[i] && G.row >= 6) {
          c.fillStyle = '#202124'; c.fillRect(x0, y + G.row - 3, Math.max(x1 - x0, 0.6), 2);
        }
      }
    }
  }

  function drawGanttCursor() {
    gctx.setTransform(1, 0, 0, 1, 0, 0);
    gctx.clearRect(0, 0, gantt.width, gantt.height);
    gctx.drawImage(gbase, 0, 0);
    gctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    if (now >= G.v0 && now <= G.v1) {
      gctx.strokeStyle = '#a142f4'; gctx.lineWidth = 1.5;
      gctx.beginPath(); gctx.moveTo(gx(now), G.top - 6); gctx.lineTo(gx(now), G.h); gctx.stroke();
    }
    if (selected && selected.type === 'agv') {
      gctx.strokeStyle = '#a142f4'; gctx.lineWidth = 1;
      gctx.strokeRect(G.label - 2, G.top + selected.a * G.row, G.w - G.label - 2, G.row);
    }
  }

  function ganttHit(e) {
    var a = Math.floor((e.offsetY - G.top) / G.row);
    if (a < 0 || a >= AGVS.length || e.offsetX < G.label) return null;
    var t = gt(e.offsetX), s = AGVS[a].s, i = upper(s.t, t) - 1;
    return {a: a, t: t, i: i >= 0 && t <= s.e[i] ? i : -1};
  }

  var gdrag = null;
  gantt.addEventListener('mousemove', function (e) {
    if (gdrag) {
      var dt = (e.offsetX - gdrag.x) / (G.w - G.label - 6) * (gdrag.v1 - gdrag.v0);
      if (Math.abs(e.offsetX - gdrag.x) > 3) gdrag.moved = true;
      if (gdrag.moved) { panGantt(gdrag.v0 - dt, gdrag.v1 - dt); return; }
    }
    var hit = ganttHit(e);
    if (!hit || hit.i < 0) { tip.style.display = 'none'; return; }
    var s = AGVS[hit.a].s, i = hit.i;
    var lines = ['AGV ' + AGVS[hit.a].id + '  ' + D.states[s.st[i]],
                 hms(s.t[i]) + ' to ' + hms(s.e[i]) + '  (' + duration(s.e[i] - s.t[i]) + ')',
                 'order ' + (s.o[i] >= 0 ? s.o[i] : 'none') + (s.l[i] ? ', loaded' : ', empty'),
                 'reason ' + S[s.ev[i]] + (S[s.det[i]] ? ': ' + S[s.det[i]] : '')];
    showTip(e, lines.join('\n'));
  });
  gantt.addEventListener('mouseleave', function () { tip.style.display = 'none'; gdrag = null; });
  gantt.addEventListener('mousedown', function (e) {
    gdrag = {x: e.offsetX, v0: G.v0, v1: G.v1, moved: false};
  });
  gantt.addEventListener('mouseup', function (e) {
    var wasDrag = gdrag && gdrag.moved;
    gdrag = null;
    if (wasDrag) return;
    var hit = ganttHit(e);
    if (!hit) return;
    selected = {type: 'agv', a: hit.a};
    seek(hit.t);
  });
  gantt.addEventListener('wheel', function (e) {
    e.preventDefault();
    var k = Math.exp(e.deltaY * 0.0015), t = gt(e.offsetX);
    var span = Math.max((G.v1 - G.v0) * k, 10);
    var lo = t - (t - G.v0) / (G.v1 - G.v0) * span;
    panGantt(lo, lo + span);
  }, {passive: false});
  gantt.addEventListener('dblclick', function () { panGantt(FROM, TO); });

  function panGantt(lo, hi) {
    var span = Math.min(hi - lo, TO - FROM);
    lo = Math.min(Math.max(lo, FROM), TO - span);
    G.v0 = lo; G.v1 = lo + span;
    drawGanttBase(); drawGanttCursor();
  }

  function showTip(e, text) {
    tip.textContent = text;
    tip.style.display = 'block';
    var x = e.clientX + 14, y = e.clientY + 12;
    if (x + tip.offsetWidth > window.innerWidth) x = e.clientX - tip.offsetWidth - 10;
    if (y + tip.offsetHeight > window.innerHeight) y = e.clientY - tip.offsetHeight - 10;
    tip.style.left = x + 'px'; tip.style.top = y + 'px';
  }

  function timelineTotals() {  // seconds drawn per AGV
    var out = {};
    AGVS.forEach(function (agv) {
      var total = 0;
      for (var i = 0; i < agv.s.t.length; i++) total += agv.s.e[i] - agv.s.t[i];
      out[agv.id] = total;
    });
    return out;
  }

  // ---- lead times: one stacked bar per order ---------------------------------------------------------
  var LEADS = D.leads, lead = document.getElementById('leadchart'), lctx = lead.getContext('2d');
  var LEAD_COLOURS = LEADS.colours;
  var L = {left: 44, top: 22, h: 220};

  function drawLeads() {
    var w = lead.clientWidth || 800;
    lead.style.height = L.h + 'px';
    lead.width = Math.round(w * dpr); lead.height = Math.round(L.h * dpr);
    var c = lctx;
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    c.clearRect(0, 0, w, L.h);
    c.font = '10px system-ui, sans-serif';
    var n = LEADS.id.length, max = 0;
    for (var i = 0; i < n; i++) max = Math.max(max, LEADS.lead[i]);
    L.w = w; L.n = n; L.max = max || 1;
    var lx = L.left;
    LEADS.labels.forEach(function (label, k) {
      c.fillStyle = LEAD_COLOURS[k]; c.fillRect(lx, 5, 10, 10);
      c.fillStyle = '#202124'; c.fillText(label, lx + 13, 14);
      lx += c.measureText(label).width + 28;
    });
    if (!n) { c.fillText('no order delivered in this window', L.left, 60); return; }
    var plotH = L.h - L.top - 16, bw = (w - L.left - 6) / n;
    c.fillStyle = '#5f6368';
    for (var k = 0; k <= 4; k++) {
      var v = L.max * k / 4, y = L.top + plotH - plotH * k / 4;
      c.fillText(v.toFixed(0) + ' s', 2, y + 3);
      c.strokeStyle = '#e8eaed'; c.beginPath(); c.moveTo(L.left, y); c.lineTo(w, y); c.stroke();
    }
    for (i = 0; i < n; i++) {
      var y0 = L.top + plotH;
      for (k = 0; k < LEADS.parts.length; k++) {
        var part = LEADS[LEADS.parts[k]][i];
        if (!(part > 0)) continue;
        var hgt = part / L.max * plotH;
        c.fillStyle = LEAD_COLOURS[k];
        c.fillRect(L.left + i * bw, y0 - hgt, Math.max(bw - (bw > 3 ? 1 : 0), 0.5), hgt);
        y0 -= hgt;
      }
    }
    c.fillStyle = '#5f6368';
    c.fillText('orders in order of creation \u2192', L.left, L.h - 3);
  }

  function leadHit(e) {
    if (!L.n || e.offsetX < L.left) return -1;
    var i = Math.floor((e.offsetX - L.left) / ((L.w - L.left - 6) / L.n));
    return i >= 0 && i < L.n ? i : -1;
  }
  lead.addEventListener('mousemove', function (e) {
    var i = leadHit(e);
    if (i < 0) { tip.style.display = 'none'; return; }
    var lines = ['order ' + LEADS.id[i] + '  AGV ' + LEADS.agv[i] + '  created ' + hms(LEADS.created[i]),
                 'lead time ' + LEADS.lead[i].toFixed(1) + ' s'];
    LEADS.parts.forEach(function (p, k) {
      var v = LEADS[p][i];
      lines.push('  ' + LEADS.labels[k] + ': ' + (v >= 0 ? v.toFixed(1) + ' s' : 'n/a'));
    });
    showTip(e, lines.join('\n'));
  });
  lead.addEventListener('mouseleave', function () { tip.style.display = 'none'; });
  lead.addEventListener('click', function (e) {
    var i = leadHit(e);
    if (i < 0) return;
    for (var a = 0; a < AGVS.length; a++) if (AGVS[a].id === LEADS.agv[i]) selected = {type: 'agv', a: a};
    seek(LEADS.created[i]);
  });

  // ---- start ----------------------------------------------------------------------------------------
  function layoutAll() {
    resize(); sizeGantt();
    drawBase(); drawGanttBase(); drawLeads(); render();
  }
  resize(); fit(); sizeGantt();
  drawBase(); drawGanttBase(); drawLeads();
  window.addEventListener('resize', layoutAll);

  window.fleetReplay = {
    positionsAt: positionsAt, zonesAt: zonesAt, seek: seek, timelineTotals: timelineTotals,
    get time() { return now; }, get drawn() { return drawn; },
    play: function () { setPlaying(true); }, pause: function () { setPlaying(false); }
  };

  var asked = /(?:^#|&)t=([0-9.eE+-]+)/.exec(window.location.hash);
  var askedAgv = /&agv=([0-9]+)/.exec(window.location.hash);
  var askedNode = /&node=([^&]+)/.exec(window.location.hash);
  for (var q = 0; askedAgv && q < AGVS.length; q++) {
    if (AGVS[q].id === Number(askedAgv[1])) selected = {type: 'agv', a: q};
  }
  if (askedNode) {
    var named = nodeOf[decodeURIComponent(askedNode[1])];
    if (named !== undefined) selected = {type: 'node', n: named};
  }
  if (/&heat=1/.test(window.location.hash)) {
    document.getElementById('ov-heat').checked = true;
    heat.on = true; computeHeat(); drawBase();
  }
  seek(asked ? Number(asked[1]) : FROM);
  if (asked) {
    var readyMs = performance.now(), frames = 60, started = performance.now();
    for (var f = 0; f < frames; f++) seek(FROM + (TO - FROM) * f / (frames - 1));
    var frameMs = (performance.now() - started) / frames;
    seek(Number(asked[1]));
    var check = document.createElement('pre');
    check.id = 'replay-check';
    check.textContent = JSON.stringify({
      readyMs: readyMs, frameMs: frameMs, info: info.textContent,
      chargers: chargersBox.textContent, zones: zonesAt(now), zonePanel: zonesBox ? zonesBox.textContent : '',
      drawnZones: drawnZones,
      t: now, positions: positionsAt(now), drawn: drawn, totals: timelineTotals(),
      window: [FROM, TO], agvs: AGVS.length,
      resources: (performance.getEntriesByType('resource') || []).length,
      violations: violations,
      floor: floor.getBoundingClientRect()
    });
    document.body.appendChild(check);
  }
})();
