"""Error codes and their levels (fleet_sim.model.error_codes), held against RSS-AGV-001 6.1."""

from __future__ import annotations

import pytest

from fleet_sim.model.error_codes import CODES, describe

# RSS-AGV-001 6.1, copied by hand; E_301 is the model's own code for a communication timeout
SPEC_6_1 = {"E_001": "Warning", "E_002": "Warning", "E_101": "Error", "E_102": "Error",
            "E_201": "Critical", "E_202": "Critical", "E_999": "Fatal"}


@pytest.mark.parametrize("code,level", sorted(SPEC_6_1.items()))
def test_each_code_of_6_1_has_its_level(code: str, level: str) -> None:
    assert describe(code)[0] == level


def test_only_e301_is_not_in_the_spec_and_it_says_so() -> None:
    assert set(CODES) - set(SPEC_6_1) == {"E_301"}
    level, text = describe("E_301")
    assert level == "Error" and "not in 6.1" in text


def test_an_unknown_code_is_described_as_an_unknown_error() -> None:
    assert describe("E_404") == ("Error", "unknown error code")
