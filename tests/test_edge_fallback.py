"""The edge's local fallback on a silent or bursty downlink (issue 16, docs/deviations.md section 17): the pure core
(`EdgeEventGenerator.overdue`, `EdgeEvents` holding its own v_x while an answer is overdue, the zero-order hold
selectable, the envelope), and the offline engine on the 20 ms Gilbert-Elliott link: the time the edge runs on a
setpoint older than the state it waits an answer to is bounded by the answer timeout (plus one check period) with
the fallback, and is not with the zero-order hold."""
from __future__ import annotations

from pathlib import Path

import pytest
from edge_lockstep_run import run_live_edge_lockstep

from sea_hil.config.loader import load_config
from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.edge_trigger import EdgeEventGenerator
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.smc import JointState, smc_deflection
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.controller.trigger import EventTrigger
from sea_hil.offline.session_engine import run_engine
from sea_hil.protocol.link import parse_link_spec
from sea_hil.protocol.payloads import TriggerReason
from sea_hil.report.session_summary import session_summary

ROOT = Path(__file__).resolve().parents[1]
MS = 1_000_000
# every deterministic block of a session summary (as tests/test_session_engine.py compares)
COMPARED = ("transmissions", "tracking", "lead_in", "events_by_reason", "inter_event_s", "duration_s",
            "uplink_outside_msgs", "max_abs_voltage_v")
EDGE = {"trigger": {"placement": "edge", "edge_model": True}, "controller": {"compensation": "predict"}}
BURSTY = "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"


def _gen() -> EdgeEventGenerator:
    traj = make_trajectory(load_config().trajectory)
    return EdgeEventGenerator(EventTrigger(1e9, 0.01, 250 * MS), traj, lead_in_ns=0, lookahead=False)


def test_overdue_after_the_answer_timeout_of_the_oldest_unanswered_state():
    gen = _gen()
    js = JointState(gen.desired(0).theta_rad, gen.desired(0).omega_rad_s)
    assert gen.on_sample(0, js)[2] is TriggerReason.INITIAL
    gen.sent(1, 0)
    assert not gen.overdue(100 * MS)                # the anchor is not answered yet: no agreed t, no fallback
    gen.answered(1, 0, 0)
    gen.sent(11, 10 * MS)
    gen.sent(21, 20 * MS)                           # a second event while the first answer is in flight
    assert gen.outstanding == [(11, 10 * MS), (21, 20 * MS)]
    assert not gen.overdue(29 * MS) and gen.overdue(30 * MS)   # 20 ms minimum timeout from the oldest (11)
    gen.answered(11, 31 * MS, 10 * MS)              # the older answer comes: 21 is still awaited, from 20 ms
    assert gen.outstanding == [(21, 20 * MS)] and not gen.overdue(31 * MS)
    assert gen.overdue(20 * MS + gen.answer_timeout_ns)
    gen.answered(21, 45 * MS, 20 * MS)
    assert gen.outstanding == [] and not gen.overdue(500 * MS)


def _core(fallback: str, **safety: dict) -> tuple[EdgeEvents, object]:
    cfg = load_config(overrides={**EDGE, "trigger": {**EDGE["trigger"], "edge_fallback": fallback}, **safety})
    inner = InnerLoop(cfg, nominal_params(cfg), tuple(cfg.plant.initial_theta_rad), 1e-3)
    return EdgeEvents(cfg, "tt", inner, MS, 10, jit=False), cfg


def _fb(theta: tuple[float, float]) -> tuple:
    return (theta, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))


def _silent_after_anchor(core: EdgeEvents, fb: tuple, until_ms: int) -> list:
    """The anchor answered at once, then every state unanswered (a silent downlink): the decisions up to `until_ms`."""
    assert core.on_sample(0, fb).reason is TriggerReason.INITIAL     # type: ignore[union-attr]
    core.answered(1, 0)
    return [core.on_sample(k * MS, fb) for k in range(10, until_ms + 1, 10)]


def test_local_fallback_holds_the_smc_law_of_the_edges_own_sample_while_overdue():
    core, cfg = _core("local")
    fb = _fb((0.1, 0.9))
    ds = _silent_after_anchor(core, fb, 60)
    assert [d.hold is not None for d in ds] == [False, False, True, True, True, True]   # from 20 ms after state 11
    desired = core.generator.desired(core.generator.time_of(60 * MS))    # x_d at the edge's (= controller's) t
    cc = cfg.controller
    expect = smc_deflection(JointState(fb[0], fb[1]), desired, nominal_params(cfg), cc.c, cc.rho, cc.boundary_layer)
    assert ds[-1].hold == expect
    st = core.fallback_stats()
    assert st["edge_fallback_samples"] == 4 and st["edge_fallback_episodes"] == 1
    core.answered(11, 65 * MS)                      # the link is back: answers end the episode
    core.answered(core.generator.outstanding[-1][0], 66 * MS)
    assert core.on_sample(70 * MS, fb).hold is None  # type: ignore[union-attr]


def test_zero_order_hold_is_selectable_and_the_envelope_applies_to_local_setpoints():
    hold_core, _ = _core("hold")
    assert all(d.hold is None for d in _silent_after_anchor(hold_core, _fb((0.1, 0.9)), 60))
    assert hold_core.fallback_stats()["edge_fallback_samples"] == 0
    tight, _ = _core("local", safety={"setpoint": {"enabled": True, "deflection_max_m": [1e-9, 1e-9]}})
    assert all(d.hold is None for d in _silent_after_anchor(tight, _fb((0.1, 0.9)), 60))
    assert tight.fallback_stats()["edge_fallback_rejected"] == 4     # computed, out of the envelope, not held


def _bursty(fallback: str) -> EdgeEvents:
    link = parse_link_spec(BURSTY)
    cfg = load_config(overrides={"link": {"seed": 1, "uplink": link, "downlink": link}, "disturbance": {"seed": 1},
                                 **EDGE, "trigger": {**EDGE["trigger"], "edge_fallback": fallback}})
    edge = run_engine(cfg, "et").edge
    assert edge is not None
    return edge


def test_stale_hold_is_bounded_by_the_answer_timeout_on_a_bursty_link():
    """Seed 1 on the 20 ms / GE link: a downlink burst leaves the edge waiting for answers; with the zero-order hold
    it runs on the old setpoint until an answer comes (beyond the answer timeout), with the fallback at most one
    check period (10 ms) beyond it."""
    period_ns = int(round(load_config().controller.sample_period_s * 1e9))
    old, new = _bursty("hold"), _bursty("local")
    assert old.max_stale_excess_ns > period_ns      # the behaviour before: the bound does not hold
    assert new.fallback_samples > 0 and new.max_stale_excess_ns < period_ns


@pytest.mark.slow
def test_live_lockstep_edge_with_the_fallback_equals_the_engine(tmp_path):
    """The live edge applies the fallback as the engine does: a lockstep session (trigger at the edge, prediction,
    10 ms and GE bursts each way, short trajectory) in which the fallback fires equals the engine bit for bit."""
    spec = "delay=10ms,ge=0.05/0.3/0.8"
    cfg_file, live = run_live_edge_lockstep(tmp_path, spec)
    link = parse_link_spec(spec)
    cfg = load_config(cfg_file, {"link": {"seed": 1, "uplink": link, "downlink": link}, "disturbance": {"seed": 1},
                                 **EDGE})
    res = run_engine(cfg, "et")
    got = session_summary(res.data, "et")
    assert res.edge is not None and res.edge.fallback_samples > 0
    assert live["edge"]["edge_fallback_samples"] == res.edge.fallback_samples
    assert {k: got[k] for k in COMPARED} == {k: live[k] for k in COMPARED}
