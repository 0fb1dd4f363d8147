"""`simulate` (the offline closed loop without a network) is the offline session engine on an ideal link where the
two describe the same loop (issue 28): the paper's scheme (every state up, the controller's trigger), no lead-in, no
drive limits or setpoint envelope, DBC-quantised feedback (`quantise=True`), the plant started at rest on the
trajectory's first sample (a CSV trajectory with zero velocity at t = 0), a disturbance. Both run the same kernel and
disturbance table: per outer sample the measured angles (as the edge decodes them) are the same floats, and so are
the samples with events, their reasons and the saturated steps. The one difference is the time base: `simulate`
evaluates the trajectory at k * dt (float seconds, the pre-restructuring figures, tests/test_pre_refactor_equality.py),
the engine at k * period_ns * 1e-9 (integer ns, as the nodes and lockstep): times and desired angles agree to an
ulp."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sea_hil.config.loader import load_config
from sea_hil.offline.closed_loop import simulate
from sea_hil.offline.session_engine import run_engine
from sea_hil.offline.wire_quantiser import dbc_resolutions, quantised
from sea_hil.protocol.payloads import TriggerReason
from sea_hil.report.session_summary import tracking_arrays

PERIOD_S = 3.0
START = (0.05, 0.2831)


def _rest_start_csv(path: Path) -> Path:
    """theta_j(t) = start_j + a_j (1 - cos(2 pi t / T)): at rest at t = 0."""
    rows = ["t,theta1,theta2"]
    for i in range(int(PERIOD_S * 100) + 1):
        w = 1.0 - math.cos(2.0 * math.pi * i * 0.01 / PERIOD_S)
        rows.append(f"{i * 0.01:.2f},{START[0] + 0.1 * w!r},{START[1] + 0.15 * w!r}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("mode", ["et", "tt"])
def test_simulate_is_the_engine_on_an_ideal_link(mode: str, tmp_path: Path) -> None:
    cfg = load_config(None, {
        "trajectory": {"kind": "csv", "csv_path": str(_rest_start_csv(tmp_path / "rest.csv")), "lead_in_s": 0.0},
        "plant": {"initial_theta_rad": list(START)},
        "trigger": {"placement": "controller", "edge_model": False}, "controller": {"compensation": "none"},
        "safety": {"drive": {"enabled": False}, "setpoint": {"enabled": False}},
        "disturbance": {"knee": {"kind": "sine", "amplitude_nm": 0.3, "frequency_hz": 1.5}}})
    sim = simulate(cfg, mode, cycles=1, quantise=True)
    eng = run_engine(cfg, mode)
    tr = tracking_arrays(eng.data)
    n = len(sim.t_s)             # the engine also answers the state at t = the cycle's end (its stop rule)
    assert len(tr["t_s"]) == n + 1
    lsb = dbc_resolutions(cfg.can.fd)
    measured = np.array([[quantised(a, lsb[0]), quantised(b, lsb[0])] for a, b in sim.theta_rad])
    np.testing.assert_array_equal(tr["theta_rad"][:n], measured)
    np.testing.assert_allclose(tr["t_s"][:n], sim.t_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(tr["desired_rad"][:n], sim.desired_rad, rtol=0, atol=1e-15)
    within = tr["event_t_s"] < PERIOD_S
    dt = 1.0 / cfg.can.feedback_rate_hz
    assert np.round(tr["event_t_s"][within] / dt).tolist() == np.round(sim.event_t_s / dt).tolist()   # same samples
    assert list(tr["reasons"][within]) == [TriggerReason(r).name for r in sim.event_reason]
    assert len(sim.event_t_s) > 10 and np.abs(sim.desired_rad - sim.theta_rad).max() < 0.05   # it tracked
    assert eng.saturated_steps >= sim.saturated_steps
