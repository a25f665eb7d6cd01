"""Closed-form trapezoidal travel times against hand formulas and a time-stepped integration."""

from __future__ import annotations

import numpy as np
import pytest

from fleet_sim.model.kinematics import distance_at, piece_time, stop_entry_speed, traverse


def gridded_time(pieces: list[tuple[float, float]], v_in: float, v_end: float, accel: float,
                 decel: float, step_m: float = 2e-4) -> float:
    """Independent check on a fine distance grid: the fastest speed at each point is the lowest
    of the local limit, what accelerating from behind allows and what braking ahead allows;
    time is the sum of step / speed."""
    return float(gridded_clock(pieces, v_in, v_end, accel, decel, step_m)[1][-1])


def gridded_clock(pieces: list[tuple[float, float]], v_in: float, v_end: float, accel: float,
                  decel: float, step_m: float = 2e-4) -> tuple[np.ndarray, np.ndarray]:
    """(distance, time) at each point of the fine grid of `gridded_time`."""
    lengths = [p[0] for p in pieces]
    n = round(sum(lengths) / step_m)
    x = np.linspace(0.0, sum(lengths), n + 1)
    edges = np.cumsum(lengths)
    # at a point exactly on a boundary both neighbouring limits apply
    idx_left = np.minimum(np.searchsorted(edges, x, side="left"), len(pieces) - 1)
    idx_right = np.minimum(np.searchsorted(edges, x, side="right"), len(pieces) - 1)
    limits = np.array([p[1] for p in pieces])
    cap = np.minimum(limits[idx_left], limits[idx_right])
    v = cap.copy()
    v[0] = min(v[0], v_in)
    dx = x[1] - x[0]
    for i in range(1, n + 1):
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * accel * dx))
    v[n] = min(v[n], v_end)
    for i in range(n - 1, -1, -1):
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * decel * dx))
    # exact time over each small step of uniform acceleration between its end speeds
    return x, np.concatenate([[0.0], np.cumsum(2 * dx / (v[:-1] + v[1:]))])


def test_cruise_profile_by_hand() -> None:
    # 10 m at 1 m/s with 0.5 m/s2 both ways: 2 s and 1 m accelerating, 8 m cruising, 2 s braking
    assert piece_time(10, 0, 1.0, 0, 0.5, 0.5) == pytest.approx(2 + 8 + 2)


def test_triangle_profile_by_hand() -> None:
    # 1 m from rest to rest: peak sqrt(a*L) = sqrt(0.5) m/s, time 2 * peak / a
    peak = np.sqrt(0.5)
    assert piece_time(1, 0, 1.0, 0, 0.5, 0.5) == pytest.approx(2 * peak / 0.5)


def test_branch_turn_at_turn_speed() -> None:
    # a 1 m curve at 0.3 m/s (Req.Nav.005) then 3 m back up to 1 m/s
    t, v_end = traverse([(1.0, 0.3), (3.0, 1.0)], 0.3, 1.0, 0.5, 0.5)
    assert v_end == pytest.approx(1.0)
    assert t == pytest.approx(1 / 0.3 + 1.4 + (3 - 0.91))


def test_stop_entry_speed() -> None:
    assert stop_entry_speed([(4.0, 1.0)], 0.5) == pytest.approx(1.0)
    assert stop_entry_speed([(0.25, 1.0)], 0.5) == pytest.approx(0.5)
    assert stop_entry_speed([(1.0, 0.3), (3.0, 1.0)], 0.5) == pytest.approx(0.3)


@pytest.mark.parametrize("seed", range(8))
def test_closed_form_matches_a_fine_grid(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pieces = [(float(rng.uniform(0.5, 6)), float(rng.choice([0.3, 0.5, 1.0])))
              for _ in range(int(rng.integers(1, 4)))]
    v_in = min(0.3, pieces[0][1])
    v_end_max = float(rng.choice([0.0, 0.3, 1.0]))
    t_closed, v_end = traverse(pieces, v_in, v_end_max, 0.5, 0.5)
    assert t_closed == pytest.approx(gridded_time(pieces, v_in, v_end, 0.5, 0.5), abs=2e-3)


@pytest.mark.parametrize("seed", range(8))
def test_position_along_the_profile_matches_a_fine_grid(seed: int) -> None:
    """distance_at (what the replay draws) against the grid's distance at the same times."""
    rng = np.random.default_rng(100 + seed)
    pieces = [(float(rng.uniform(0.5, 6)), float(rng.choice([0.3, 0.5, 1.0])))
              for _ in range(int(rng.integers(1, 4)))]
    v_in = min(float(rng.choice([0.0, 0.3])), pieces[0][1])
    t_total, v_end = traverse(pieces, v_in, float(rng.choice([0.0, 0.3, 1.0])), 0.5, 0.5)
    x, clock = gridded_clock(pieces, v_in, v_end, 0.5, 0.5)
    for t in np.linspace(0.0, t_total, 41):
        grid_m = float(np.interp(t, clock, x))
        assert distance_at(pieces, v_in, v_end, 0.5, 0.5, float(t)) == pytest.approx(
            grid_m, abs=2e-3)
    length = sum(p[0] for p in pieces)
    assert distance_at(pieces, v_in, v_end, 0.5, 0.5, t_total) == pytest.approx(length, abs=1e-9)
    assert distance_at(pieces, v_in, v_end, 0.5, 0.5, t_total + 5) == length
    assert distance_at(pieces, v_in, v_end, 0.5, 0.5, 0.0) == 0.0
