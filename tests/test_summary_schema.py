"""summary.json has one schema (sea_hil/report/summary_schema.py) for `simulate`, `run` and `report`; the old
layouts (offline `transmissions` an int, timing fields at the top level) are rejected by it."""
from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from test_session_summary import _session  # a synthetic recording: states, tracking records, setpoints

from sea_hil.config.loader import load_config
from sea_hil.offline.simulate import run_simulation
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary_schema import SUMMARY_SCHEMA

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "pre_refactor"


def test_the_schema_is_valid_json_schema() -> None:
    jsonschema.Draft202012Validator.check_schema(SUMMARY_SCHEMA)


def test_offline_summary_matches_the_schema(tmp_path: Path) -> None:
    cfg = load_config(overrides={"trajectory": {"period_s": 1.0}})
    s = run_simulation(cfg, "et", tmp_path, None)
    jsonschema.validate(s, SUMMARY_SCHEMA)
    jsonschema.validate(json.loads((tmp_path / "summary.json").read_text(encoding="utf-8")), SUMMARY_SCHEMA)


def test_session_summary_matches_the_schema() -> None:
    s = session_summary(_session(20, 170, range(1, 176), {20, 30, 100}), "et")
    jsonschema.validate(s, SUMMARY_SCHEMA)
    jsonschema.validate({**s, "lockstep": True, "inner": "edge", "timing": {**s["timing"], "wall_s": 1.0}},
                        SUMMARY_SCHEMA)


@pytest.mark.parametrize("name", ["sim_et", "run_et_ideal"])
def test_the_pre_refactor_layouts_are_rejected(name: str) -> None:
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(json.loads((FIXTURES / f"{name}.summary.json").read_text(encoding="utf-8")),
                            SUMMARY_SCHEMA)
