"""The vehicle as a scenario describes it: kinematics, body, sub-state times and battery.

Defaults come from RSS-AGV-001 section 7.1 where the spec gives a figure, "assumed" where not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fleet_sim.errors import InputError


@dataclass(frozen=True)
class BatteryProfile:
    capacity_wh: float = 960.0
    """Assumed: a 24 V, 40 Ah traction battery."""
    drive_wh_per_m: float = 0.04
    """Assumed: about 150 W at 1 m/s, empty."""
    drive_loaded_wh_per_m: float = 0.06
    """Assumed: 50 % more with a load."""
    handling_w: float = 100.0
    """Assumed: transfer conveyor or lift while loading or unloading."""
    idle_w: float = 20.0
    """Assumed: controller, sensors and Wi-Fi while standing."""
    initial_soc_pct: float = 90.0
    cc_until_pct: float = 80.0
    """Assumed: constant-current charging up to here, then tapering."""
    taper_end_share: float = 0.2
    """Assumed: at 100 % the charge rate has fallen to this share of the constant-current rate."""
    charge_efficiency: float = 0.9
    """Assumed: share of charger power that ends up in the battery."""

    def check(self, file: str, element: str) -> None:
        for name in ("capacity_wh", "charge_efficiency", "taper_end_share"):
            if getattr(self, name) <= 0:
                raise InputError(file, f"{element}.{name}", getattr(self, name), "a number > 0")
        for name in ("drive_wh_per_m", "drive_loaded_wh_per_m", "handling_w", "idle_w"):
            if getattr(self, name) < 0:
                raise InputError(file, f"{element}.{name}", getattr(self, name), "a number >= 0")
        for name in ("initial_soc_pct", "cc_until_pct"):
            if not 0 <= getattr(self, name) <= 100:
                raise InputError(file, f"{element}.{name}", getattr(self, name),
                                 "a percentage in [0, 100]")
        if self.charge_efficiency > 1 or self.taper_end_share > 1:
            raise InputError(file, f"{element}.charge_efficiency", self.charge_efficiency,
                             "a share in (0, 1]")

    def pct_per_wh(self) -> float:
        return 100.0 / self.capacity_wh


@dataclass(frozen=True)
class VehicleProfile:
    name: str = "rss-agv-001"
    max_speed_mps: float = 1.0
    """P_001 VEL_MAX 1000 mm/s."""
    accel_mps2: float = 0.5
    """P_002 VEL_ACC 500 mm/s2."""
    decel_mps2: float = 0.5
    """P_003 VEL_DEC 500 mm/s2."""
    turn_speed_mps: float = 0.3
    """P_004 TURN_SPEED 300 mm/s; Req.Nav.005 limits branch turns to 0.3 m/s."""
    length_m: float = 1.0
    """Assumed: body length of a typical tape-guided tugger/carrier."""
    min_gap_m: float = 0.5
    """Gap kept to the AGV ahead; P_006 OBS_STOP_DIST 500 mm, the distance the LDS stops at."""
    boot_s: float = 5.0
    """Assumed: time in ST_001 Booting before Event_Init_Complete."""
    approach_s: float = 1.5
    """Assumed: L_Approach, the precise approach to a station (4.3)."""
    handshake_s: float = 1.0
    """Assumed: L_Handshake, the I/O handshake with the station (4.3)."""
    verify_s: float = 0.5
    """Assumed: L_Verify, checking the load is seated (4.3). L_Transfer is the station's
    handling time."""
    spin_s: float = 6.0
    """Assumed: a 180-degree spin on the spot (5.3 TYPE_CMD 0x10)."""
    battery: BatteryProfile = field(default_factory=BatteryProfile)

    def check(self, file: str, element: str) -> None:
        for name in ("max_speed_mps", "accel_mps2", "decel_mps2", "turn_speed_mps", "length_m"):
            value = getattr(self, name)
            if value <= 0:
                raise InputError(file, f"{element}.{name}", value, "a number > 0")
        for name in ("min_gap_m", "boot_s", "approach_s", "handshake_s", "verify_s", "spin_s"):
            value = getattr(self, name)
            if value < 0:
                raise InputError(file, f"{element}.{name}", value, "a number >= 0")
        if self.turn_speed_mps > self.max_speed_mps:
            raise InputError(file, f"{element}.turn_speed_mps", self.turn_speed_mps,
                             f"at most max_speed_mps ({self.max_speed_mps})")
