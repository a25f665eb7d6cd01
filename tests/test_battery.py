"""The state of charge and the charge curve, against figures worked out by hand."""

from __future__ import annotations

import math

import pytest

from fleet_sim.config.vehicle import BatteryProfile
from fleet_sim.model.battery import StateOfCharge, charge_time_s

# 1000 Wh, every watt from the 1 kW charger into the battery: r0 = 1000 W / 3600 * 0.1 %/Wh
# = 1/36 %/s, so 10 % take 360 s at constant current (up to 80 %). Above 80 % the rate falls
# linearly to 20 % of r0 at 100 %: c = 0.8 / 20 = 0.04 per %.
PROFILE = BatteryProfile(capacity_wh=1000.0, charge_efficiency=1.0, cc_until_pct=80.0,
                         taper_end_share=0.2, idle_w=36.0, drive_wh_per_m=0.05,
                         drive_loaded_wh_per_m=0.1, initial_soc_pct=50.0)


def test_constant_current_part_by_hand() -> None:
    assert charge_time_s(PROFILE, 20.0, 80.0, 1.0) == pytest.approx(2160.0, rel=1e-12)
    assert charge_time_s(PROFILE, 20.0, 30.0, 2.0) == pytest.approx(180.0, rel=1e-12)


def test_taper_part_by_hand() -> None:
    # 80 -> 95 %: -ln(1 - 0.04 * 15) / (0.04 / 36) = 36 ln(2.5) / 0.04 = 824.662 s
    assert charge_time_s(PROFILE, 80.0, 95.0, 1.0) == pytest.approx(824.6620, abs=1e-3)
    # across the knee: 2160 s below 80 % plus the taper
    assert charge_time_s(PROFILE, 20.0, 95.0, 1.0) == pytest.approx(2160.0 + 824.6620, abs=1e-3)
    # the taper is slower than constant current would be
    assert charge_time_s(PROFILE, 80.0, 95.0, 1.0) > 15 * 36


def test_no_time_to_charge_down() -> None:
    assert charge_time_s(PROFILE, 60.0, 60.0, 1.0) == 0.0
    assert charge_time_s(PROFILE, 60.0, 40.0, 1.0) == 0.0


def test_without_taper_the_curve_is_straight() -> None:
    flat = BatteryProfile(capacity_wh=1000.0, charge_efficiency=1.0, cc_until_pct=100.0)
    assert charge_time_s(flat, 50.0, 95.0, 1.0) == pytest.approx(45 * 36.0, rel=1e-12)


def test_idle_draw_driving_and_charging_by_hand() -> None:
    soc = StateOfCharge(PROFILE, 0.0)
    # 36 W for an hour is 36 Wh = 3.6 % of 1000 Wh
    assert soc.soc_pct(3600.0) == pytest.approx(46.4, abs=1e-12)
    assert soc.seconds_until(3600.0, 40.0) == pytest.approx(6.4 / 3.6 * 3600.0, rel=1e-12)
    # 100 m loaded at 0.1 Wh/m: 10 Wh = 1 %
    soc.drive(3600.0, 100.0, loaded=True)
    assert soc.soc_pct(3600.0) == pytest.approx(45.4, abs=1e-12)
    soc.draw(3600.0, 0.0)  # on the charger: no draw
    assert soc.seconds_until(3600.0, 10.0) == math.inf
    assert soc.soc_pct(7200.0) == pytest.approx(45.4, abs=1e-12)
    soc.set_soc(7200.0, 95.1)
    assert soc.soc_pct(7200.0) == 95.1
