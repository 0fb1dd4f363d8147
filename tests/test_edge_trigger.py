"""The sensor-side event generator (trigger at the edge) and the placements of the offline engine."""
from __future__ import annotations

from sea_hil.config.loader import load_config
from sea_hil.controller.edge_trigger import EdgeEventGenerator
from sea_hil.controller.smc import JointState
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.controller.trigger import EventTrigger
from sea_hil.offline.session_engine import EngineOptions, run_engine
from sea_hil.protocol.link import parse_link_spec
from sea_hil.protocol.payloads import TriggerReason
from sea_hil.report.session_summary import session_summary

MS = 1_000_000


def _gen(threshold: float = 0.05, r: float = 10.0) -> EdgeEventGenerator:
    traj = make_trajectory(load_config().trajectory)
    return EdgeEventGenerator(EventTrigger(threshold, r, 250 * MS), traj, lead_in_ns=0, lookahead=False)


def _on_track(gen: EdgeEventGenerator, t_ns: int, offset: float = 0.0) -> TriggerReason | None:
    ds = gen.desired(t_ns)
    return gen.on_sample(t_ns, JointState((ds.theta_rad[0] + offset, ds.theta_rad[1]), ds.omega_rad_s))[2]


def _anchored(gen: EdgeEventGenerator) -> None:
    """The first sample is the anchor (INITIAL); the controller answers it at once."""
    assert _on_track(gen, 0) is TriggerReason.INITIAL
    gen.sent(1, 0)
    gen.answered(1, 0, 0)
    assert gen.anchored and gen.anchor_seq == 1


def test_first_sample_is_an_event_and_on_track_needs_only_heartbeats():
    gen = _gen()
    _anchored(gen)
    fired = []
    for k in range(1, 60):                      # 0.6 s exactly on the trajectory, each event answered at once
        reason = _on_track(gen, k * 10 * MS)
        if reason is not None:
            fired.append(reason)
            gen.sent(10 * k + 1, k * 10 * MS)
            gen.answered(10 * k + 1, k * 10 * MS, k * 10 * MS)
    assert fired and all(r in (TriggerReason.ERROR_BOUND, TriggerReason.HEARTBEAT) for r in fired)


def test_no_duplicate_events_while_an_answer_is_in_flight_then_retrigger_after_timeout():
    gen = _gen(threshold=1e9, r=0.01)           # only the r rule can fire: it would fire at every sample
    _anchored(gen)
    assert _on_track(gen, 10 * MS, offset=0.1) is TriggerReason.TRACKING_BOUND
    gen.sent(11, 10 * MS)
    assert _on_track(gen, 11 * MS, offset=0.1) is None            # X~ > r, but the answer is in flight
    assert _on_track(gen, 29 * MS, offset=0.1) is None
    assert _on_track(gen, 30 * MS, offset=0.1) is TriggerReason.TRACKING_BOUND   # timeout (20 ms): re-trigger
    assert gen.retriggers == 1
    gen.sent(31, 30 * MS)
    gen.answered(31, 40 * MS, 30 * MS)           # answered (RTT 10 ms), the next event may fire at once
    assert gen.awaiting_seq is None and gen.rtt_ns == 0.125 * 10 * MS
    assert _on_track(gen, 41 * MS, offset=0.1) is TriggerReason.TRACKING_BOUND


def test_error_moving_fires_even_while_an_answer_is_in_flight():
    gen = _gen(threshold=0.05)
    _anchored(gen)
    assert _on_track(gen, 1 * MS, offset=0.2) is TriggerReason.ERROR_BOUND
    gen.sent(2, 1 * MS)
    assert _on_track(gen, 2 * MS, offset=0.21) is None          # moved less than the threshold
    assert _on_track(gen, 3 * MS, offset=0.4) is TriggerReason.ERROR_BOUND


def test_the_anchor_is_republished_until_the_controller_answers_it():
    """Issue 16's real-time failure: the edge counted t from its first sample whether or not the controller (still
    starting) received it. Now nothing but the anchor goes out until it is answered, and an unanswered anchor is
    replaced after one heartbeat period; only the answer to the current anchor confirms it."""
    traj = make_trajectory(load_config().trajectory)
    gen = EdgeEventGenerator(EventTrigger(0.05, 10.0, 250 * MS), traj, lead_in_ns=500 * MS, lookahead=False)
    t, _, reason = gen.on_sample(7 * MS, JointState((0.05, 0.3), (0.0, 0.0)))     # any clock origin
    assert (t, reason) == (-500 * MS, TriggerReason.INITIAL)
    gen.sent(8, 7 * MS)
    for k in range(1, 25):                      # nobody answers: no event, however far the error moves
        assert gen.on_sample(7 * MS + k * 10 * MS, JointState((0.05 + 0.01 * k, 0.3), (0.0, 0.0)))[2] is None
    t, _, reason = gen.on_sample(257 * MS, JointState((0.4, 0.3), (0.0, 0.0)))
    assert (t, reason) == (-500 * MS, TriggerReason.INITIAL) and gen.reanchors == 1   # t starts over here
    assert gen.lead_in is not None and gen.lead_in.sample(-0.5).theta_rad[0] == 0.4   # the lead-in from here
    gen.sent(258, 257 * MS)
    gen.answered(8, 260 * MS, 7 * MS)           # a late answer to the old anchor: applied, but no confirmation
    assert not gen.anchored and gen.on_sample(267 * MS, JointState((0.4, 0.3), (0.0, 0.0)))[2] is None
    gen.answered(258, 268 * MS, 257 * MS)
    assert gen.anchored and gen.on_sample(277 * MS, JointState((0.9, 0.3), (0.0, 0.0)))[2] is not None


def test_no_answer_for_the_setpoint_timeout_reanchors():
    gen = _gen()
    _anchored(gen)
    gen.reanchor_after_ns = 500 * MS
    assert _on_track(gen, 490 * MS) is not None        # heartbeat (unanswered from here on)
    gen.sent(491, 490 * MS)
    assert _on_track(gen, 500 * MS) is TriggerReason.INITIAL and gen.reanchors == 1 and not gen.anchored


def test_refused_answers_keep_the_anchor_and_the_link_alive():
    """An answer the edge refuses (outside the setpoint envelope: a drive latched in a fault cannot follow, so the
    lead-in's setpoints grow) is still an answer: it confirms the anchor and holds off the silence re-anchor, which
    had restarted the lead-in every `reanchor_after_ns` so the cycles never began; the answer in flight stays."""
    gen = _gen()
    assert _on_track(gen, 0) is TriggerReason.INITIAL
    gen.sent(1, 0)
    gen.heard(1, 0)                                    # the anchor's answer, refused
    assert gen.anchored and gen.awaiting_seq == 1 and gen.rtt_ns is None and gen.outstanding == [(1, 0)]
    gen.reanchor_after_ns = 500 * MS
    for k in range(1, 100):                            # 1 s of answers, every one refused: t runs on
        t_ns = k * 10 * MS
        if _on_track(gen, t_ns, offset=0.3) is not None:
            gen.sent(t_ns // MS + 1, t_ns)
        gen.heard(t_ns // MS + 1, t_ns)
    assert gen.reanchors == 0 and gen.time_of(990 * MS) == 990 * MS
    assert _on_track(gen, 1500 * MS, offset=0.3) is TriggerReason.INITIAL and gen.reanchors == 1   # silence: still


def _summary(link: str, opts: EngineOptions) -> dict:
    ov = {"link": {"seed": 1}}
    if link:
        ov["link"].update(uplink=parse_link_spec(link), downlink=parse_link_spec(link))
    cfg = load_config(None, ov)
    return session_summary(run_engine(cfg, "et", opts=opts).data, "et")


def test_edge_placement_makes_both_directions_event_triggered():
    paper = _summary("", EngineOptions())
    edge = _summary("", EngineOptions(placement="edge"))
    tp, te = paper["transmissions"], edge["transmissions"]
    assert tp["uplink_msgs"] > 250 and te["uplink_msgs"] <= te["downlink_msgs"] + 1     # one state per setpoint
    assert te["uplink_msgs"] + te["downlink_msgs"] < 0.6 * (tp["uplink_msgs"] + tp["downlink_msgs"])
    assert max(edge["tracking"]["max_abs_error_rad"]) < 1.2 * max(paper["tracking"]["max_abs_error_rad"])


def test_prediction_removes_most_of_a_fixed_delay():
    delayed = _summary("delay=10ms", EngineOptions())
    predicted = _summary("delay=10ms", EngineOptions(compensation="predict"))
    ideal = _summary("", EngineOptions())
    assert max(delayed["tracking"]["max_abs_error_rad"]) > 10 * max(ideal["tracking"]["max_abs_error_rad"])
    assert max(predicted["tracking"]["max_abs_error_rad"]) < 1.5 * max(ideal["tracking"]["max_abs_error_rad"])
