"""What happens to the AGV on a hop: battery use, markers, dead spots, obstacles, line losses.

The AGV's side of the driver's `DriverHost` (fleet_sim.sim.agents.driving: `travel`, `arrived`,
`speed_cap_mps`) and of the LDS watch's `PausedHost` (fleet_sim.sim.agents.lds).

Obstacles (4.2.3/4.2.4): met while driving; seen for < 300 ms they only slow the AGV (the
P_005/P_006 zone), otherwise it pauses until the path has been clear for 2000 ms; E_101 after
5 minutes paused. Scripted blocks stop AGVs in front of the blocked segment. A line lost
(Req.Err.010) is found again (warning E_001) or raises E_202.
"""

from __future__ import annotations

import math

from fleet_sim.config.layout_spec import MARKER_SPEED_MPS
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.driving import Proc
from fleet_sim.sim.agents.vehicle_base import SegmentFacts, VehicleBase


class VehicleTravel(VehicleBase):
    """The hop's incidents and markers, and the pauses behind an AGV ahead."""

    def speed_cap_mps(self) -> float | None:
        """DriverHost: markers and slow modes cap the next hop's speed."""
        cap = self.marker_speed_mps
        if not self.fms_link and self.rules.comm_policy == "req_err_011":
            slow = self.rules.comm_loss_speed_mps
            cap = slow if cap is None else min(cap, slow)
        return cap

    def travel(self, u: str, v: str, time_s: float) -> Proc:
        """DriverHost: drive the hop, with dead spots, blocks, obstacles and line losses."""
        facts = self._segment_facts.get((u, v))
        if facts is None:
            facts = self._segment_facts[u, v] = self._facts_of(u, v)
        dead, weak, obstacle_p, line_p = facts
        if dead != self.in_dead_spot:
            self.in_dead_spot = dead
            self.recorder.comm_losses += dead
            self.note("dead_spot_in" if dead else "dead_spot_out", f"{u} -> {v}")
            self._link_changed()
        if weak:
            self.recorder.warning("E_002")
        traffic = self.traffic
        if traffic.blocks:
            blocked_until = traffic.blocked_until(u, v, self.env.now)
            if blocked_until is not None:
                yield from self._obstacle(blocked_until - self.env.now,
                                          f"segment {u} -> {v} blocked")
        rng = self.incident_rng
        if obstacle_p is not None and rng.random() < obstacle_p:
            share = float(rng.random())
            edge = traffic.routes.edge[u, v]
            duration = edge["obstacle_duration"] or self.incidents.obstacle_duration
            yield from self.driver.move(u, v, time_s, share)
            yield from self._obstacle(duration.sample(rng), f"on {u} -> {v}")
            yield from self.driver.move(u, v, time_s, 1.0)
        else:
            yield from self.driver.move(u, v, time_s, 1.0)
        if line_p is not None and rng.random() < line_p:
            if rng.random() < self.incidents.line_found_prob:
                self.recorder.warning("E_001")
                self.note("line_lost", f"found again within {self.rules.line_keep_heading_m} m")
                yield from self.driver.pause(self.incidents.line_search_s)
            else:
                self.fail_now("E_202")

    def _facts_of(self, u: str, v: str) -> SegmentFacts:
        """Segment u -> v as `travel` sees it: a dead spot, a weak signal, the chance of an
        obstacle on it and of losing the line on it (None: no chance, no draw)."""
        edge = self.traffic.routes.edge[u, v]
        length = edge["length_m"]
        rate = edge["obstacle_rate_per_km"]
        if rate is None:
            rate = self.incidents.obstacle_rate_per_km
        line_rate = self.incidents.line_loss_per_km
        return (edge["rssi_dbm"] < self.rules.link_min_rssi_dbm,
                edge["rssi_dbm"] < self.rules.weak_rssi_dbm,
                1.0 - math.exp(-rate * length / 1000.0) if rate > 0 else None,
                1.0 - math.exp(-line_rate * length / 1000.0) if line_rate > 0 else None)

    def _obstacle(self, seen_s: float, where: str) -> Proc:
        """An obstacle appears in front and stays within range for `seen_s` seconds.

        Seen for less than 300 ms (4.2.3), it only slows the AGV through the detection zone
        (P_005/P_006): braking to the creep speed and speeding up again cost time. Seen longer,
        the AGV pauses 300 ms after it appeared and drives on 2000 ms after it has gone (4.2.4);
        paused for 5 minutes, it raises E_101.
        """
        rules = self.rules
        motion = self.routes.motion
        v = max(self.speed_mps, min(self.profile.max_speed_mps, 1.0))
        self._obstacle_near_s = seen_s
        if self.traffic.motion_backend is not None:
            yield from self._obstacle_held(seen_s, where)
            return
        if seen_s < rules.obstacle_pause_s:
            slow = min(rules.obstacle_slow_speed_mps, v)
            extra = (v - slow) / motion.decel_mps2 + (v - slow) / motion.accel_mps2 \
                - (v * v - slow * slow) * (1 / motion.decel_mps2 + 1 / motion.accel_mps2) / (2 * v)
            self.note("obstacle_slowdown", f"{where}: seen {seen_s:.2f} s")
            yield self.env.timeout(extra + seen_s * (1 - slow / v))
            return
        yield self.env.timeout(rules.obstacle_pause_s)
        self.fire("Event_Obstacle_Detected", f"{where}: within 1.0 m for "
                                              f">= {rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.obstacle_pauses += 1
        wait = seen_s - rules.obstacle_pause_s + rules.obstacle_clear_s
        if wait >= rules.obstacle_timeout_s:
            yield self.env.timeout(rules.obstacle_timeout_s)
            self.fail_now("E_101")
        yield self.env.timeout(wait)
        self._obstacle_clear_s = rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {wait:.2f} s")
        yield self.env.timeout(v / (2 * motion.accel_mps2))  # speeding up again from a stop

    def _obstacle_held(self, seen_s: float, where: str) -> Proc:
        """`_obstacle` with a motion backend: the same rules, but the backend brakes the AGV
        (to the creep speed, or to a stop) and speeds it up again, so the time lost is its
        own, and AGVs behind it close up."""
        rules = self.rules
        if seen_s < rules.obstacle_pause_s:
            self.note("obstacle_slowdown", f"{where}: seen {seen_s:.2f} s")
            yield from self.driver.pause(seen_s, rules.obstacle_slow_speed_mps)
            return
        yield from self.driver.pause(rules.obstacle_pause_s, rules.obstacle_slow_speed_mps)
        self.fire("Event_Obstacle_Detected", f"{where}: within 1.0 m for "
                                              f">= {rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.obstacle_pauses += 1
        wait = seen_s - rules.obstacle_pause_s + rules.obstacle_clear_s
        if wait >= rules.obstacle_timeout_s:
            yield from self.driver.pause(rules.obstacle_timeout_s)
            self.fail_now("E_101")
        yield from self.driver.pause(wait)
        self._obstacle_clear_s = rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {wait:.2f} s")

    def pause_for_agv(self, ahead: int, gap_m: float) -> bool:
        """PausedHost: the AGV ahead stands within the LDS's stop distance (4.2.3)."""
        if self.state is not VehicleState.MOVING or self.failing:
            return False
        self._obstacle_near_s = self.rules.obstacle_pause_s
        self.fire("Event_Obstacle_Detected",
                  f"AGV {ahead} {gap_m:.2f} m ahead for >= "
                  f"{self.rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.agv_obstacle_pauses += 1
        return True

    def resume_after_agv(self, paused_s: float) -> None:
        """PausedHost: the way has been clear long enough (4.2.4)."""
        self._obstacle_clear_s = self.rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {paused_s:.2f} s behind an AGV")

    def arrived(self, v: str, length_m: float) -> Proc | None:
        """DriverHost: battery use and markers at `v`; a spin or a pause marker is a stop,
        returned to be driven (None: none)."""
        self.battery.drive(self.env.now, length_m, self.loaded)
        marker = self.traffic.layout.markers.get(v)
        if marker is not None:
            if marker == "spin" or marker == "pause":
                return self._stop_at_marker(v, marker)
            if marker in MARKER_SPEED_MPS:
                self.marker_speed_mps = MARKER_SPEED_MPS[marker]
            elif marker == "location":
                self._position_known = True
            self.note(f"marker_{marker}", v)
        if self.battery.soc_pct(self.env.now) < self.rules.bat_critical_pct:
            self.fail_now("E_201")
        return None

    def _stop_at_marker(self, v: str, marker: str) -> Proc:
        """A spin or a pause marker at `v`: the AGV stops there."""
        if marker == "spin":
            yield self.env.timeout(self.profile.spin_s)
        else:
            yield self.env.timeout(self.rules.marker_pause_s)
        self.note(f"marker_{marker}", v)
        if self.soc_pct < self.rules.bat_critical_pct:
            self.fail_now("E_201")

