"""Issue 15 in a networked lockstep session: a constant disturbance on both joints and a 20 % mass / stiffness
mismatch at once, ET, the paper's 10 s cycle (`sea-hil run --lockstep` composes the same nodes)."""
from __future__ import annotations

from pathlib import Path

import pytest
from paper_scheme import paper

from sea_hil.config.shorthand import scenario_config
from sea_hil.session.run import RunOptions, run_session

pytestmark = pytest.mark.slow


def test_lockstep_session_rejects_disturbance_and_mismatch(tmp_path: Path) -> None:
    # issue 15's bounds, measured with the paper's scheme (a state up every sample: the setpoint ratio below)
    cfg = scenario_config(None, paper(), "hip=constant:0.5Nm,knee=constant:0.05Nm", "mass=+20%,stiffness=-20%")
    s = run_session(cfg, RunOptions(controller="et", out=tmp_path / "run", lockstep=True, progress=False, figures=False,
                                    seed=1))
    assert max(s["tracking"]["max_abs_error_rad"]) <= 0.01, s["tracking"]
    tx = s["transmissions"]
    assert tx["downlink_msgs"] <= 0.40 * tx["uplink_msgs"]  # TT sends one setpoint per state
    assert s["edge"]["saturated_steps"] <= 0.01 * s["edge"]["commands_sent"]
