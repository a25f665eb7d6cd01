"""The time-stepped vehicle model (agv_model.dynamics): ramps, cruise, closed-form agreement,
PID line following, markers, turns, stops and latency, line loss, determinism."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from agv_model.dynamics import (
    Drive,
    Start,
    State,
    Stop,
    StopAt,
    Trace,
    VehicleParams,
    simulate,
)
from agv_model.line_sensor import LineSensor
from agv_model.pid import PidGains
from agv_model.track import Marker, Straight, TagType, Track
from userfiles.checking import InputError, validate

ACC = 0.5  # P_002 / P_003, m/s2
DT = 0.01


def trapezoid_s(length_m: float, v_max: float, acc: float = ACC) -> float:
    """Stop-to-stop time by hand: accelerate, cruise, brake, all at `acc`."""
    if length_m >= v_max * v_max / acc:
        return length_m / v_max + v_max / acc
    return 2.0 * math.sqrt(length_m / acc)  # triangle: never reaches v_max


def drive(track: Track, speed_mps: float, **kwargs: Any) -> Trace:
    return simulate(track, [Drive(0.0, speed_mps)], **kwargs)


# ---- speed ----------------------------------------------------------------------------------

def test_ramps_follow_vel_acc_and_vel_dec_exactly_per_step() -> None:
    trace = drive(Track.straight(6.0), 1.0)
    dv = np.diff(trace.speed_mps)
    accel = dv[dv > 1e-12]
    brake = dv[dv < -1e-12][:-1]  # the last step comes to rest within the step
    assert len(accel) == 200 and len(brake) > 150  # 2 s of ramp each way at 10 ms
    assert np.allclose(accel, ACC * DT, rtol=0, atol=1e-12)
    assert np.allclose(brake, -ACC * DT, rtol=0, atol=1e-12)
    assert trace.speed_mps[0] == 0.0 and trace.speed_mps[-1] == 0.0


def test_cruise_speed_is_reached_and_held() -> None:
    trace = drive(Track.straight(8.0), 0.5)
    cruising = np.array([s is State.CRUISE for s in trace.state])
    assert trace.speed_mps.max() == pytest.approx(0.5, abs=1e-12)
    assert np.all(trace.speed_mps[cruising] == pytest.approx(0.5, abs=1e-12))
    # 8 m at 0.5 m/s: 0.25 m ramping each way, 7.5 m = 15 s held
    assert cruising.sum() * DT == pytest.approx(15.0, abs=2 * DT)


def test_speed_never_exceeds_vel_max() -> None:
    trace = drive(Track.straight(6.0), 5.0)
    assert trace.speed_mps.max() == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("length_m", [0.3, 1.0, 2.0, 5.0, 12.0])
@pytest.mark.parametrize("v_max", [0.5, 1.0])
def test_straight_run_time_matches_the_closed_form_trapezoid(length_m: float,
                                                            v_max: float) -> None:
    # Tolerance 1 ms (a tenth of a step): braking is planned so the stop lands on the target,
    # and the step that comes to rest is timed within the step.
    trace = drive(Track.straight(length_m), v_max)
    assert trace.stop_time_s is not None
    assert trace.stop_time_s == pytest.approx(trapezoid_s(length_m, v_max), abs=1e-3)
    assert trace.final_position_m == pytest.approx(length_m, abs=1e-6)


def test_smaller_step_gives_the_same_run() -> None:
    coarse = drive(Track.straight(5.0), 1.0, start=Start(lateral_error_m=0.02))
    fine = drive(Track.straight(5.0), 1.0, start=Start(lateral_error_m=0.02), dt_s=0.005)
    assert coarse.stop_time_s == pytest.approx(fine.stop_time_s, abs=1e-3)
    assert fine.final_position_m == pytest.approx(5.0, abs=1e-3)


def test_time_at_interpolates_within_a_step() -> None:
    trace = drive(Track.straight(10.0), 1.0)
    # accelerating from rest at 0.5 m/s2: x = t^2 / 4
    assert trace.time_at(0.5) == pytest.approx(math.sqrt(2.0), abs=1e-6)
    assert trace.time_at(5.0) == pytest.approx(2.0 + 4.0, abs=1e-6)  # 1 m ramp, then 4 s
    with pytest.raises(ValueError, match="never reached 11"):
        trace.time_at(11.0)


# ---- markers, turns -------------------------------------------------------------------------

def test_speed_markers_change_the_cruise_speed() -> None:
    track = Track.straight(14.0, (Marker.speed(3.0, 0.5), Marker.speed(7.0, 0.2),
                                  Marker.speed(9.0, 1.0)))
    trace = drive(track, 1.0)

    def speed_at(x: float) -> float:
        return float(trace.speed_mps[np.searchsorted(trace.position_m, x)])

    assert speed_at(2.9) == pytest.approx(1.0)
    assert speed_at(6.5) == pytest.approx(0.5)  # 0.75 m braking after the tag at 3 m
    assert speed_at(8.9) == pytest.approx(0.2)
    assert speed_at(11.0) == pytest.approx(1.0)
    tags = [e for e in trace.events if e.what.startswith("tag TYPE_SPD")]
    assert [round(e.position_m, 1) for e in tags] == [3.0, 7.0, 9.0]


def test_bad_markers_are_refused() -> None:
    with pytest.raises(ValueError, match="0x04"):
        Marker(1.0, TagType.SPD, 0x04)
    with pytest.raises(ValueError, match="spin"):
        Marker(1.0, TagType.CMD, 0x10)
    with pytest.raises(ValueError, match="off the track"):
        Track.straight(2.0, (Marker.speed(3.0, 0.5),))


def test_pause_marker_stops_for_three_seconds() -> None:
    trace = drive(Track.straight(6.0, (Marker(2.0, TagType.CMD, 0x20),)), 0.5)
    rests = [e for e in trace.events if e.what == "at rest"]
    over = [e for e in trace.events if e.what == "pause over"]
    assert len(rests) == 2 and len(over) == 1
    assert over[0].time_s - rests[0].time_s == pytest.approx(3.0, abs=DT)
    assert rests[0].position_m == pytest.approx(2.0 + 0.25, abs=0.01)  # 0.5^2 / (2 x 0.5)
    assert trace.final_position_m == pytest.approx(6.0, abs=1e-6)


def test_branch_curve_is_driven_at_the_turn_speed() -> None:
    track = Track.branch(4.0, 4.0)  # 90 degrees over a 1 m curve after the node at 4 m
    trace = drive(track, 1.0)
    on_curve = (trace.odometer_m >= 4.0) & (trace.odometer_m < 5.0)
    assert trace.speed_mps[on_curve].max() <= 0.3 + 1e-12
    assert trace.speed_mps[on_curve].min() == pytest.approx(0.3, abs=1e-12)
    assert trace.speed_mps.max() == pytest.approx(1.0)  # back up to speed after the curve
    assert State.LINE_LOST not in trace.state
    assert np.abs(trace.sensor_error_m).max() < 0.01  # the sensor stays within 10 mm
    assert trace.heading_rad[-1] == pytest.approx(math.pi / 2, abs=0.02)


# ---- steering -------------------------------------------------------------------------------

def _worst_after(trace: Trace, from_m: float) -> float:
    return float(np.abs(trace.lateral_error_m[trace.position_m >= from_m]).max())


@pytest.mark.parametrize("speed_mps", [0.2, 0.5, 1.0])
def test_pid_removes_a_20_mm_offset(speed_mps: float) -> None:
    trace = drive(Track.straight(5.0), speed_mps,
                  start=Start(speed_mps=speed_mps, lateral_error_m=0.020))
    assert _worst_after(trace, 2.0) < 0.005  # within the sensor's 5 mm step after 2 m
    assert State.LINE_LOST not in trace.state


def test_the_p_gain_matters() -> None:
    def worst(gains: PidGains) -> float:
        trace = drive(Track.straight(5.0), 0.5, params=VehicleParams(pid=gains),
                      start=Start(speed_mps=0.5, lateral_error_m=0.020))
        return _worst_after(trace, 2.0)

    assert worst(PidGains()) < 0.005
    assert worst(PidGains(kp=0.0)) > 0.010  # I and D alone leave it swinging


def test_gains_are_the_spec_defaults() -> None:
    gains = PidGains()
    assert (gains.kp, gains.ki, gains.kd) == (1.25, 0.05, 0.80)  # P_007, P_008, P_009


def test_line_sensor_is_16_bit_and_quantised() -> None:
    sensor = LineSensor()
    assert sensor.bits(0.0) == 0b0000_0011_1100_0000  # 4 elements over the tape, centred
    assert sensor.read_m(0.0) == 0.0
    assert sensor.read_m(0.002) == 0.0  # within the 2.5 mm dead band
    assert sensor.read_m(0.004) == pytest.approx(0.005)
    assert sensor.read_m(-0.011) == pytest.approx(-0.010)
    assert sensor.read_m(0.097) == pytest.approx(0.075)  # one element left at the edge
    assert sensor.bits(0.098) == 0 and sensor.read_m(0.098) is None
    assert sensor.bits(None) == 0
    with pytest.raises(ValueError, match="beyond 16"):
        sensor.reading_m(1 << 16)


def test_line_lost_holds_steering_then_errors_after_50_cm() -> None:
    trace = drive(Track.straight(5.0), 0.5, start=Start(lateral_error_m=0.15))
    whats = [e.what for e in trace.events]
    assert "line lost (all sensors off)" in whats
    err = next(e for e in trace.events if e.what.startswith("error"))
    assert err.position_m == pytest.approx(0.5, abs=0.02)
    assert trace.state[-1] is State.ERROR
    assert trace.final_position_m == pytest.approx(0.5 + 0.25, abs=0.02)  # then brakes


def test_a_short_gap_in_the_tape_is_driven_through() -> None:
    trace = drive(Track((Straight(6.0),), gaps=((2.0, 2.3),)), 0.5)
    whats = [e.what for e in trace.events]
    assert "line lost (all sensors off)" in whats and "line found" in whats
    assert State.ERROR not in trace.state
    assert trace.final_position_m == pytest.approx(6.0, abs=1e-6)


# ---- stops and latency ----------------------------------------------------------------------

@pytest.mark.parametrize("station_m", [4.0, 4.0037, 4.0081])
def test_stop_at_a_station_within_10_mm_at_low_speed(station_m: float) -> None:
    trace = simulate(Track.straight(8.0), [Drive(0.0, 0.2), StopAt(0.0, station_m)])
    assert abs(trace.final_position_m - station_m) <= 0.010
    assert trace.state[-1] is State.STOPPED


def _host_timed_stop(speed_mps: float, latency_s: float, station_m: float = 5.0) -> float:
    """Stop error when the host sends 'stop' as the vehicle passes the braking point."""
    track = Track.straight(10.0)
    start = Start(speed_mps=speed_mps)
    free = simulate(track, [Drive(0.0, speed_mps)], start=start)
    sent_s = free.time_at(station_m - speed_mps ** 2 / (2 * ACC))
    trace = simulate(track, [Drive(0.0, speed_mps), Stop(sent_s)], start=start,
                     link_delay_s=latency_s)
    return trace.final_position_m - station_m


def test_a_prompt_stop_command_lands_within_10_mm_at_low_speed() -> None:
    assert abs(_host_timed_stop(0.2, 0.0, station_m=5.0)) <= 0.010
    assert abs(_host_timed_stop(0.2, 0.0, station_m=5.0013)) <= 0.010


@pytest.mark.parametrize(("speed_mps", "latency_s"), [(0.5, 0.1), (1.0, 0.05), (0.2, 0.25)])
def test_a_late_stop_command_overshoots_by_speed_times_latency(speed_mps: float,
                                                               latency_s: float) -> None:
    overshoot = _host_timed_stop(speed_mps, latency_s, station_m=5.0033)
    # plus up to one control step of waiting for the command to be picked up
    assert speed_mps * latency_s - 1e-6 <= overshoot <= speed_mps * (latency_s + DT) + 1e-6


def test_a_drive_command_takes_effect_after_its_link_delay() -> None:
    trace = simulate(Track.straight(3.0), [Drive(0.0, 0.5)], link_delay_s=0.25)
    moving = np.nonzero(trace.speed_mps > 0)[0]
    assert trace.time_s[moving[0]] == pytest.approx(0.25 + DT)  # applied at the 0.25 s step
    assert trace.state[0] is State.IDLE
    per_command = simulate(Track.straight(3.0), [Drive(0.0, 0.5, delay_s=0.0)],
                           link_delay_s=0.25)
    assert trace.stop_time_s is not None
    assert per_command.stop_time_s == pytest.approx(trace.stop_time_s - 0.25)


def test_vehicle_stays_idle_without_a_command() -> None:
    trace = simulate(Track.straight(3.0))
    assert len(trace.time_s) == 1 and trace.state == (State.IDLE,)


def test_bad_inputs_name_the_value() -> None:
    with pytest.raises(ValueError, match=r"dt_s \(0\)"):
        simulate(Track.straight(1.0), dt_s=0)
    with pytest.raises(ValueError, match="speed_mps > 0"):
        simulate(Track.straight(1.0), [Drive(0.0, 0.0)])
    with pytest.raises(ValidationError, match="decel_mps2"):
        VehicleParams(decel_mps2=-1.0)
    with pytest.raises(InputError, match=r"^params: decel_mps2: got -1.0; expected a number > 0$"):
        validate(VehicleParams, {"decel_mps2": -1.0}, "params")
    with pytest.raises(InputError, match=r"^params: pause_s: got nan; expected a finite number$"):
        validate(VehicleParams, {"pause_s": float("nan")}, "params")


# ---- determinism, output --------------------------------------------------------------------

def _noisy(seed: int) -> Trace:
    track = Track.branch(3.0, 3.0)
    track = Track(track.pieces, (Marker(1.0, TagType.LOC, 1), Marker.speed(2.0, 0.5)))
    return simulate(track, [Drive(0.0, 1.0), StopAt(0.0, 5.5)],
                    VehicleParams(tag_jitter_m=0.003), seed=seed,
                    start=Start(lateral_error_m=0.01))


def test_same_inputs_same_trace() -> None:
    a, b = _noisy(7), _noisy(7)
    for name in ("time_s", "position_m", "odometer_m", "speed_mps", "lateral_error_m",
                 "heading_rad", "steer_rad"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.state == b.state and a.events == b.events
    assert a.records() == b.records()
    assert not np.array_equal(a.position_m, _noisy(8).position_m)  # the seed is used


def test_records_carry_the_trace_fields() -> None:
    trace = drive(Track.straight(1.0), 0.5)
    first, last = trace.records()[0], trace.records()[-1]
    assert first.time_s == 0.0 and first.state is State.IDLE
    assert last.speed_mps == 0.0 and last.state is State.STOPPED
    assert last.position_m == pytest.approx(1.0)


def test_plot_writes_a_png(tmp_path: Path) -> None:
    from agv_model.dynamics_plot import plot_trace

    out = plot_trace(drive(Track.branch(1.0, 1.5), 0.5), tmp_path / "sub" / "trace.png", "t")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_dynamics_never_imports_fleet_sim() -> None:
    code = ("import sys, agv_model.dynamics, agv_model.dynamics_plot; "
            "sys.exit(any(m.split('.')[0] == 'fleet_sim' for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
