"""The vehicle as a scenario describes it: kinematics, body, sub-state times and battery.

Defaults come from RSS-AGV-001 section 7.1 where the spec gives a figure, "assumed" where not.

Decisions, where the issue is silent:

* ``battery: off`` (YAML ``off``, ``false`` or ``null``) is the switch for the battery model:
  no drain, no charging, no battery thresholds; SOC is not recorded. The model holds None and
  the resolved config writes ``battery: null``. ``on``/``true`` is refused: write the figures
  (or leave the key out for the defaults). The battery is a property of the vehicle, so the
  switch sits with its figures rather than at the top of the scenario.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field, field_validator, model_validator
from pydantic.config import JsonDict

from agv_model.inputs import NonNegative, Percent, Positive, Problem, StrictModel, Text

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
