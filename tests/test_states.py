"""The ten vehicle states (fleet_sim.model.states): spec ids and KPI keys."""

from __future__ import annotations

from fleet_sim.model.states import VehicleState


def test_ten_states_with_their_spec_ids() -> None:
    assert [s.spec_id for s in VehicleState] == [f"ST_{i:03d}" for i in range(1, 11)]
    assert [s.value for s in VehicleState] == ["Booting", "Idle", "Moving", "Loading", "Unloading",
                                        "Charging", "Paused", "Error", "Maintenance", "SafeMode"]


def test_kpi_keys_are_the_lower_case_names() -> None:
    assert VehicleState.SAFE_MODE.key == "safe_mode"
    assert VehicleState.IDLE.key == "idle"
    assert len({s.key for s in VehicleState}) == 10
