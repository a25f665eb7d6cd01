"""State of charge of one AGV: drained by driving, handling and idling; filled by a charge curve.

The charge curve is constant current up to `cc_until_pct`, then the rate tapers linearly to
`taper_end_share` of the constant-current rate at 100 %. Charge times are closed form:
with s the SOC and r0 the constant-current rate (% per second),
    ds/dt = r0                                       for s < cc
    ds/dt = r0 * (1 - c (s - cc)),  c = (1 - k) / (100 - cc)   above,
so the tapering part takes  -ln((1 - c (s2 - cc)) / (1 - c (s1 - cc))) / (r0 c)  seconds.
"""

from __future__ import annotations

import math

from fleet_sim.config.vehicle import BatteryProfile


class StateOfCharge:
    """One AGV's state of charge over time: from a continuous draw (idle, handling) and
    per-metre use. (The battery's data is `BatteryProfile`; agv_model's `Battery` is a vehicle
    profile's figures, not this.)"""

    def __init__(self, profile: BatteryProfile, now_s: float) -> None:
        self.profile = profile
        self._pct_per_wh = profile.pct_per_wh()
        self._soc = profile.initial_soc_pct
        self._draw_w = profile.idle_w
        self._since_s = now_s

    def soc_pct(self, now_s: float) -> float:
        return self._soc - self._draw_w * (now_s - self._since_s) / 3600.0 \
            * self._pct_per_wh

    def settle(self, now_s: float) -> None:
        self._soc, self._since_s = self.soc_pct(now_s), now_s

    def draw(self, now_s: float, watts: float) -> None:
        """From now on, a continuous draw of `watts` (idle, handling)."""
        self.settle(now_s)
        self._draw_w = watts

    def drive(self, now_s: float, length_m: float, loaded: bool) -> None:
        self.settle(now_s)
        per_m = self.profile.drive_loaded_wh_per_m if loaded else self.profile.drive_wh_per_m
        self._soc -= per_m * length_m * self._pct_per_wh

    def seconds_until(self, now_s: float, soc_pct: float) -> float:
        """Time until the continuous draw alone takes the SOC down to `soc_pct` (inf if never)."""
        soc = self.soc_pct(now_s)
        if soc <= soc_pct:
            return 0.0
        if self._draw_w <= 0:
            return math.inf
        return (soc - soc_pct) / (self._draw_w / 3600.0 * self._pct_per_wh)

    def set_soc(self, now_s: float, soc_pct: float) -> None:
        """After charging (or a manual recharge by an operator)."""
        self.settle(now_s)
        self._soc = soc_pct


def charge_time_s(profile: BatteryProfile, from_pct: float, to_pct: float,
              power_kw: float) -> float:
    """Seconds on a charger of `power_kw` to go from `from_pct` to `to_pct`."""
    if to_pct <= from_pct:
        return 0.0
    r0 = power_kw * 1000.0 * profile.charge_efficiency / 3600.0 * profile.pct_per_wh()  # %/s
    cc = profile.cc_until_pct
    total = 0.0
    if from_pct < cc:
        upto = min(to_pct, cc)
        total += (upto - from_pct) / r0
        from_pct = upto
    if to_pct > from_pct:
        c = (1.0 - profile.taper_end_share) / (100.0 - cc) if cc < 100 else 0.0
        if c == 0.0:
            total += (to_pct - from_pct) / r0
        else:
            total += -math.log((1 - c * (to_pct - cc)) / (1 - c * (from_pct - cc))) / (r0 * c)
    return total

