"""The JSON Schema of each file a user writes (`fleet-sim schema layout|scenario|experiment|
profile`), generated from the same models that load the files, so an editor that validates YAML
as it is typed (a ``# yaml-language-server: $schema=...`` first line) agrees with fleet-sim.
`lif` and `factsheet` give the schemas of fleet-sim's own models of the two standard formats it
reads (VDMA LIF 1.0.0, VDA 5050 2.1.0 factsheet).

What a schema cannot say, the loaders still check and report: references between elements
(a segment's node exists, a flow's station is a pickup), the graph (every node reachable), the
scenario against its layout and the experiment's design points.
"""

from __future__ import annotations

from typing import Any, Final

from pydantic import BaseModel

from agv_model.profile import ProfileFile
from fleet_sim.config.experiment import ExperimentSpec
from fleet_sim.config.layout_spec import LayoutSpec
from fleet_sim.config.scenario import Scenario
from fleet_sim.config.standards.factsheet import Factsheet
from fleet_sim.config.standards.lif import LifFile

SCHEMA_URI: Final = "https://json-schema.org/draft/2020-12/schema"
FILE_MODELS: Final[dict[str, type[BaseModel]]] = {
    "layout": LayoutSpec, "scenario": Scenario, "experiment": ExperimentSpec,
    "profile": ProfileFile, "lif": LifFile, "factsheet": Factsheet,
}
"""The model of each file kind."""


def json_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of file kind `kind` (a key of FILE_MODELS), keys as users write them."""
    model = FILE_MODELS[kind]
    schema = model.model_json_schema(by_alias=True, mode="validation")
    return {"$schema": SCHEMA_URI, "$id": f"fleet-sim/{kind}.schema.json", **schema}
