"""The live trigger at the edge (issue 16) without Zenoh: the edge's pure core (`EdgeEvents`: which samples cross
the uplink, the tracking record of each outer sample, no duplicate while an answer is in flight, re-trigger after
the answer timeout), the trajectory identity, the remote controller answering event states (and refusing another
trajectory), and the controller's import boundary (never the plant)."""
from __future__ import annotations

import subprocess
import sys
import uuid

from paper_scheme import paper

from sea_hil.config.loader import load_config
from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.trajectory import trajectory_id
from sea_hil.controller.trigger import EventTrigger
from sea_hil.protocol.payloads import EventStatePayload, StatePayload, TriggerReason, encode
from sea_hil.session.builder import SessionBuilder

MS = 1_000_000
EDGE = {"trigger": {"placement": "edge", "edge_model": True}, "controller": {"compensation": "predict"}}


def _core(mode: str = "et") -> EdgeEvents:
    cfg = load_config(overrides=EDGE)
    inner = InnerLoop(cfg, nominal_params(cfg), tuple(cfg.plant.initial_theta_rad), 1e-3)
    return EdgeEvents(cfg, mode, inner, MS, 10, jit=False)   # plain Python: no compile in a unit test


def _rest(cfg_theta: tuple[float, float]) -> tuple:
    return (cfg_theta, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))


def test_edge_core_checks_outer_samples_publishes_events_and_records_every_outer_sample():
    core = _core()
    fb = _rest(tuple(load_config().plant.initial_theta_rad))
    first = core.on_sample(0, fb)
    assert first is not None and first.reason is TriggerReason.INITIAL and (first.seq, first.event_seq) == (1, 1)
    assert first.record is not None and first.record["event"] and first.record["state_seq"] == 1
    assert all(core.on_sample(k * MS, fb) is None for k in range(1, 10))       # between outer samples: not checked
    second = core.on_sample(10 * MS, fb)
    assert second is not None and second.seq == 11 and second.record is not None
    assert second.reason is None                 # the answer to state 1 is in flight: no duplicate event
    core.answered(1, 6 * MS)
    assert core.generator.awaiting_seq is None and core.generator.rtt_ns == 6 * MS
    assert core.stats() == {"edge_events": 1, "edge_retriggers": 0, "edge_reanchors": 0, "edge_resume_anchors": 0}


def test_a_drive_cleared_inside_the_lead_in_re_anchors_from_the_state_it_runs_again_in():
    """The edge cleared the drive's safe state (an edge or controller restart: the first commands met the faulted
    drive) while the anchor's lead-in was running: the next checked sample is a new anchor (INITIAL), its lead-in
    from that sample's state, so x_d has not run ahead of a limb that could not follow. Once in the measured cycles
    a clear does not move t."""
    core = _core()
    theta0 = tuple(load_config().plant.initial_theta_rad)
    assert core.on_sample(0, _rest(theta0)).reason is TriggerReason.INITIAL
    core.answered(1, 2 * MS)
    t0 = core.generator.t0_ns
    moved = ((theta0[0] + 0.02, theta0[1]), (0.1, 0.0), (0.0, 0.0), (0.0, 0.0))
    assert core.drive_cleared(95 * MS) is True
    again = core.on_sample(100 * MS, moved)
    assert again is not None and again.reason is TriggerReason.INITIAL and again.seq == 101
    g = core.generator
    assert g.t0_ns == 100 * MS + (t0 - 0) and not g.anchored and g.anchor_seq == 101
    assert g.desired(g.time_of(100 * MS)).theta_rad == moved[0]        # the lead-in starts where the limb is
    assert core.stats()["edge_resume_anchors"] == 1 and core.stats()["edge_reanchors"] == 0
    core.answered(101, 102 * MS)
    assert core.drive_cleared(g.t0_ns + 5 * MS) is False and g.t0_ns is not None   # measured cycles: t continues
    assert core.stats()["edge_resume_anchors"] == 1


def test_edge_core_retriggers_when_the_answer_is_lost():
    core = _core("et")
    # a trigger whose r rule fires on every sample (r < 0): the gate alone keeps duplicates back while in flight
    core.generator.trigger = EventTrigger(float("inf"), -1.0, 10**18)
    fb = _rest(tuple(load_config().plant.initial_theta_rad))
    assert core.on_sample(0, fb).reason is TriggerReason.INITIAL    # type: ignore[union-attr]  (the anchor)
    core.answered(1, 0)
    reasons = [core.on_sample(k * 10 * MS, fb).reason for k in range(1, 6)]  # type: ignore[union-attr]
    bound = TriggerReason.TRACKING_BOUND
    assert reasons == [bound, None, bound, None, bound]
    assert core.stats()["edge_retriggers"] == 2          # lost after the 20 ms minimum timeout: re-triggered


def test_tt_at_the_edge_publishes_every_outer_sample_whatever_is_in_flight():
    """Issue 29: a time-triggered sensor does not wait for answers (the ET gate made TT stop-and-wait): every outer
    sample is published, also before the anchor is answered and with every earlier state unanswered; answers to
    several states in flight are matched by state_seq; 1 kHz samples between outer ones are not checked even with
    `trigger.edge_check = "sample"`."""
    cfg = load_config(overrides={**EDGE, "trigger": {**EDGE["trigger"], "edge_check": "sample"}})
    inner = InnerLoop(cfg, nominal_params(cfg), tuple(cfg.plant.initial_theta_rad), 1e-3)
    core = EdgeEvents(cfg, "tt", inner, MS, 10, jit=False)
    fb = _rest(tuple(cfg.plant.initial_theta_rad))
    published = []
    for k in range(0, 101):
        d = core.on_sample(k * MS, fb)
        if k % 10:
            assert d is None                             # not an outer sample: not checked
            continue
        assert d is not None and d.reason is not None    # (EdgeEvents tells its generator it was sent)
        published.append((d.seq, d.reason))
    assert [seq for seq, _ in published] == list(range(1, 102, 10))
    assert published[0][1] is TriggerReason.INITIAL
    assert {r for _, r in published[1:]} == {TriggerReason.TIME}
    assert len(core.generator.outstanding) == 11          # nothing answered: all in flight, none held back
    core.answered(1, 101 * MS)                            # the anchor's answer, then a later one (31): by state_seq
    core.answered(31, 102 * MS)
    assert core.generator.anchored and [s for s, _ in core.generator.outstanding] == list(range(41, 102, 10))
    assert core.stats()["edge_retriggers"] == 0 and core.stats()["edge_reanchors"] == 0


def test_trajectory_identity(tmp_path):
    cfg = load_config()
    assert trajectory_id(cfg.trajectory) == trajectory_id(load_config().trajectory)
    assert trajectory_id(cfg.trajectory) != trajectory_id(load_config(overrides={"trajectory": {"period_s": 5.0}})
                                                          .trajectory)
    csv = tmp_path / "t.csv"
    csv.write_text("t_s,theta1_rad,theta2_rad\n0,0,0\n1,0.1,0.2\n", encoding="utf-8")
    a = trajectory_id(load_config(overrides={"trajectory": {"kind": "csv", "csv_path": str(csv)}}).trajectory)
    csv.write_text("t_s,theta1_rad,theta2_rad\n0,0,0\n1,0.1,0.3\n", encoding="utf-8")
    b = trajectory_id(load_config(overrides={"trajectory": {"kind": "csv", "csv_path": str(csv)}}).trajectory)
    assert a != b                                        # same parameters, other CSV bytes


def _event_state(seq: int, event_seq: int, traj: int, sample_ns: int,
                 reason: TriggerReason = TriggerReason.ERROR_BOUND) -> bytes:
    th = tuple(load_config().plant.initial_theta_rad)
    return encode(EventStatePayload(seq, sample_ns, sample_ns, th, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), event_seq,
                                    reason, traj))


def test_remote_controller_answers_every_event_state_and_refuses_another_trajectory():
    cfg = load_config(overrides={**EDGE, "can": {"interface": f"virtual:ee-{uuid.uuid4().hex[:8]}"}})
    mine = trajectory_id(cfg.trajectory)
    with SessionBuilder(cfg) as b:
        ctrl = b.controller(b.zenoh(listen=(), connect=()), "et")
        ctrl.handle(_event_state(1, 1, mine ^ 1, 0), now_ns=0)
        assert ctrl.trajectory_mismatches == 1 and ctrl.setpoint_seq == 0
        ctrl.handle(encode(StatePayload(2, 0, 10 * MS, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))), now_ns=0)
        assert ctrl.unexpected_payloads == 1            # a paper-path STATE to an edge-trigger controller
        ctrl.handle(_event_state(11, 1, mine, 10 * MS), now_ns=0)      # before any anchor: nothing to answer
        assert ctrl.setpoint_seq == 0 and ctrl.stats_dict()["unanchored_states"] == 1
        for i, k in enumerate((20, 50, 51, 90)):        # gaps in the header seq are normal
            reason = TriggerReason.INITIAL if i == 0 else TriggerReason.ERROR_BOUND    # the edge's anchor first
            ctrl.handle(_event_state(k + 1, i + 2, mine, k * MS, reason), now_ns=0)
        assert ctrl.setpoint_seq == 4 and ctrl.seq.lost == 0
        assert ctrl.t0_ns == 20 * MS + ctrl.lead_in_ns          # t counts from the anchor
        ctrl.handle(_event_state(131, 7, mine, 130 * MS), now_ns=0)    # event 6 lost on the link
        assert ctrl.setpoint_seq == 5 and ctrl.seq.lost == 1
        assert ctrl.predictor is not None and ctrl.predictor.predictions > 0
        assert ctrl.predictor.clamped > 0     # these stamps are not on the test's monotonic clock: clamped, counted


def test_the_controller_never_imports_the_plant():
    code = ("import sys, sea_hil.controller.remote, sea_hil.controller.edge, sea_hil.controller.predictor; "
            "sys.exit(any(m.startswith('sea_hil.plant_emulator') for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], timeout=120).returncode == 0


def test_controller_core_is_pure_state_in_messages_out():
    """The remote controller's core without any Zenoh: the paper's placement answers with a setpoint and a record."""
    from sea_hil.controller.remote_core import ControllerCore
    core = ControllerCore(load_config(overrides=paper()), "tt")
    th = tuple(load_config().plant.initial_theta_rad)
    ans = core.on_state(StatePayload(1, 0, 0, th, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)), lambda p: 0, lambda: 7)
    assert ans is not None and [c for c, _ in ans.messages] == ["setpoint"] and ans.record is not None
    assert ans.setpoint is not None and ans.setpoint.reason is TriggerReason.TIME and core.states == 1
    late = StatePayload(2, 0, 11 * 10**9, th, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))   # past the 10 s cycle
    assert core.on_state(late, lambda p: 0, lambda: 8) is None and core.done


def test_a_controller_that_starts_listening_late_runs_the_edges_trajectory_time():
    """Issue 16's real-time failure, on the two pure cores: in `sea-hil run` the controller process subscribes some
    100 ms to seconds after the edge's first sample. The edge used to count t from that first sample and the
    controller from the first state it received, so the controller ran the trajectory shifted by its start-up time
    (0.13-0.28 rad max error in real time). Now both count from the anchor the controller answered."""
    from sea_hil.controller.remote_core import ControllerCore
    cfg = load_config(overrides={"trigger": {"placement": "edge"}})
    inner = InnerLoop(cfg, nominal_params(cfg), tuple(cfg.plant.initial_theta_rad), 1e-3)
    edge, ctrl = EdgeEvents(cfg, "et", inner, MS, 10, jit=False), ControllerCore(cfg, "et")
    tid, fb = trajectory_id(cfg.trajectory), _rest(tuple(cfg.plant.initial_theta_rad))
    base_ns = 123_450 * MS                      # the edge's sample clock has its own origin
    answered = 0
    for k in range(0, 1200, 10):
        now = base_ns + k * MS
        d = edge.on_sample(now, fb)
        if d is None or d.reason is None or k < 300:     # the controller listens from 300 ms on
            continue
        p = EventStatePayload(d.seq, now, now, *fb, d.event_seq, d.reason, tid)
        ans = ctrl.on_state(p, lambda p: p.sample_t_ns, lambda: 0)
        if ans is not None and ans.setpoint is not None:
            edge.answered(d.seq, now)
            answered += 1
            assert p.sample_t_ns - ctrl.t0_ns == edge.generator.time_of(now)   # the same t at both ends
    assert answered > 0 and edge.generator.anchored and edge.stats()["edge_reanchors"] >= 1
