"""The vehicle as a scenario describes it: kinematics, body, sub-state times and battery.

Defaults come from RSS-AGV-001 section 7.1 where the spec gives a figure, "assumed" where not.

The choices where the issues were silent: docs/background/decisions/config.md.
"""

from __future__ import annotations

from typing import Annotated, Any, Final

from pydantic import Field, field_validator, model_validator
from pydantic.config import JsonDict

from agv_model.profile import Kinematics
from agv_model.profile import Profile as AgvModelProfile
from userfiles.checking import NonNegative, Percent, Positive, Problem, StrictModel, Text

ShareAboveZero = Annotated[float, Field(gt=0, le=1)]


class BatteryProfile(StrictModel):
    capacity_wh: Positive = 960.0
    """Assumed: a 24 V, 40 Ah traction battery."""
    drive_wh_per_m: NonNegative = 0.04
    """Assumed: about 150 W at 1 m/s, empty."""
    drive_loaded_wh_per_m: NonNegative = 0.06
    """Assumed: 50 % more with a load."""
    handling_w: NonNegative = 100.0
    """Assumed: transfer conveyor or lift while loading or unloading."""
    idle_w: NonNegative = 20.0
    """Assumed: controller, sensors and Wi-Fi while standing."""
    initial_soc_pct: Percent = 90.0
    cc_until_pct: Percent = 80.0
    """Assumed: constant-current charging up to here, then tapering."""
    taper_end_share: ShareAboveZero = 0.2
    """Assumed: at 100 % the charge rate has fallen to this share of the constant-current rate."""
    charge_efficiency: ShareAboveZero = 0.9
    """Assumed: share of charger power that ends up in the battery."""

    def pct_per_wh(self) -> float:
        return 100.0 / self.capacity_wh


def _battery_off_schema(schema: JsonDict) -> None:
    """Publish ``false`` (YAML ``off``) beside the battery's figures and ``null``."""
    variants = schema.get("anyOf")
    if isinstance(variants, list):
        variants.insert(1, {"const": False})


class VehicleProfile(StrictModel):
    name: Text = "rss-agv-001"
    max_speed_mps: Positive = 1.0
    """P_001 VEL_MAX 1000 mm/s."""
    accel_mps2: Positive = 0.5
    """P_002 VEL_ACC 500 mm/s2."""
    decel_mps2: Positive = 0.5
    """P_003 VEL_DEC 500 mm/s2."""
    turn_speed_mps: Positive = 0.3
    """P_004 TURN_SPEED 300 mm/s; Req.Nav.005 limits branch turns to 0.3 m/s."""
    length_m: Positive = 1.0
    """Assumed: body length of a typical tape-guided tugger/carrier."""
    min_gap_m: NonNegative = 0.5
    """Gap kept to the AGV ahead; P_006 OBS_STOP_DIST 500 mm, the distance the LDS stops at."""
    boot_s: NonNegative = 5.0
    """Assumed: time in ST_001 Booting before Event_Init_Complete."""
    approach_s: NonNegative = 1.5
    """Assumed: L_Approach, the precise approach to a station (4.3)."""
    handshake_s: NonNegative = 1.0
    """Assumed: L_Handshake, the I/O handshake with the station (4.3)."""
    verify_s: NonNegative = 0.5
    """Assumed: L_Verify, checking the load is seated (4.3). L_Transfer is the station's
    handling time."""
    spin_s: NonNegative = 6.0
    """Assumed: a 180-degree spin on the spot (5.3 TYPE_CMD 0x10)."""
    battery: BatteryProfile | None = Field(default=BatteryProfile(),
                                           json_schema_extra=_battery_off_schema)
    """The battery's figures; off (false, null): no battery model (no drain, no charging)."""

    @field_validator("battery", mode="before")
    @classmethod
    def _battery_off(cls, value: Any) -> Any:
        if value is False or value is None or value == "off":
            return None
        if not isinstance(value, dict | BatteryProfile):
            raise Problem("", value, "a mapping of battery figures, or off (no battery model: "
                                     "no drain, no charging)")
        return value

    @model_validator(mode="after")
    def _turn_within_top_speed(self) -> VehicleProfile:
        if self.turn_speed_mps > self.max_speed_mps:
            raise Problem("turn_speed_mps", self.turn_speed_mps,
                          f"at most max_speed_mps ({self.max_speed_mps})")
        return self


MM_PER_M: Final = 1000
"""agv_model's profiles are in the documents' millimetres; the scenario's vehicle in metres."""
MM_DIGITS: Final = 6
"""Metres written in mm are rounded to the nanometre: 1.1 m/s is 1100 mm/s, not
1100.0000000000002."""
KINEMATICS_MM: Final = {"max_speed_mps": "max_speed_mmps", "accel_mps2": "accel_mmps2",
                        "decel_mps2": "decel_mmps2", "turn_speed_mps": "turn_speed_mmps",
                        "length_m": "length_mm"}
"""A `VehicleProfile` kinematics field -> the agv_model profile's, in mm."""


def kinematics_m(kinematics: Kinematics) -> dict[str, float]:
    """An agv_model profile's kinematics as a `VehicleProfile`'s fields: mm, mm/s, mm/s2 ->
    m, m/s, m/s2, one to one."""
    return {field_m: getattr(kinematics, field_mm) / MM_PER_M
            for field_m, field_mm in KINEMATICS_MM.items()}


def mm(metres: float) -> float:
    """A length, speed or acceleration in metres as a profile writes it (mm, rounded to
    `MM_DIGITS`)."""
    return round(metres * MM_PER_M, MM_DIGITS)


LOADED_DRIVE_FACTOR = 1.5
"""Assumed, as the defaults above: driving loaded costs 50 % more energy per metre."""


def vehicle_from_profile(profile: AgvModelProfile) -> dict[str, Any]:
    """The fields of a `VehicleProfile` taken from an agv_model profile (a bundled one, or one
    written by `fleet-sim profile import` from a VDA 5050 factsheet), as plain data.

    The bridge, where the two models differ in units and in what they carry:

    * kinematics: mm, mm/s, mm/s2 -> m, m/s, m/s2 (top speed, acceleration, deceleration, turn
      speed, length); one to one.
    * battery: the profile's `moving_w` is the mean power while driving, in W; the scenario
      drains the battery per metre. At the profile's top speed a metre takes 1 / v seconds, so
      ``drive_wh_per_m = moving_w / (max_speed_mps * 3600)``, and loaded 1.5 times that
      (`LOADED_DRIVE_FACTOR`, the scenario's own assumption). `capacity_wh` and `idle_w` carry
      over; `charge_w` does not: a charge is as fast as the layout's charger (`power_kw`).
      Handling power, initial SOC and the charge curve keep the scenario's defaults.
    * everything else (min_gap_m, boot and station sub-state times, spin): the scenario's
      defaults, since a profile does not carry them.
    """
    kinematics = kinematics_m(profile.kinematics)
    bat = profile.battery
    drive_wh_per_m = bat.moving_w / (kinematics["max_speed_mps"] * 3600.0)
    return {
        "name": profile.name,
        **kinematics,
        "battery": {
            "capacity_wh": bat.capacity_wh,
            "drive_wh_per_m": round(drive_wh_per_m, 9),
            "drive_loaded_wh_per_m": round(drive_wh_per_m * LOADED_DRIVE_FACTOR, 9),
            "idle_w": bat.idle_w,
        },
    }
