"""The sensor-side event generator (trigger at the edge) and the placements of the offline engine."""
from __future__ import annotations

from sea_hil.config import load_config
from sea_hil.controller.edge_trigger import EdgeEventGenerator
from sea_hil.controller.smc import JointState
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.controller.trigger import EventTrigger, TriggerReason
from sea_hil.offline.session_engine import run_engine
from sea_hil.offline.session_loop import EngineOptions
from sea_hil.protocol.link import parse_link_spec
from sea_hil.report.session_summary import session_summary

MS = 1_000_000


def _gen(threshold: float = 0.05, r: float = 10.0) -> EdgeEventGenerator:
    traj = make_trajectory(load_config().trajectory)
    return EdgeEventGenerator(EventTrigger(threshold, r, 250 * MS), traj, lead_in_ns=0, lookahead=False)


def _on_track(gen: EdgeEventGenerator, t_ns: int, offset: float = 0.0) -> TriggerReason | None:
    ds = gen.desired(t_ns)
    return gen.on_sample(t_ns, JointState((ds.theta_rad[0] + offset, ds.theta_rad[1]), ds.omega_rad_s))[2]


def test_first_sample_is_an_event_and_on_track_needs_only_heartbeats():
    gen = _gen()
    reasons = [_on_track(gen, k * 10 * MS) for k in range(60)]       # 0.6 s exactly on the trajectory
    assert reasons[0] is TriggerReason.INITIAL
    fired = [(k, r) for k, r in enumerate(reasons) if r is not None][1:]
    assert all(r in (TriggerReason.ERROR_BOUND, TriggerReason.HEARTBEAT) for _, r in fired)


def test_no_duplicate_events_while_an_answer_is_in_flight_then_retrigger_after_timeout():
    gen = _gen(threshold=1e9, r=0.01)           # only the r rule can fire: it would fire at every sample
    assert _on_track(gen, 0) is TriggerReason.INITIAL
    gen.sent(1, 0)
    assert _on_track(gen, 1 * MS, offset=0.1) is None            # X~ > r, but the answer is in flight
    assert _on_track(gen, 19 * MS, offset=0.1) is None
    assert _on_track(gen, 20 * MS, offset=0.1) is TriggerReason.TRACKING_BOUND   # timeout (20 ms): re-trigger
    assert gen.retriggers == 1
    gen.sent(21, 20 * MS)
    gen.answered(21, 30 * MS, 20 * MS)           # answered: RTT 10 ms measured, next event may fire at once
    assert gen.awaiting_seq is None and gen.rtt_ns == 10 * MS
    assert _on_track(gen, 31 * MS, offset=0.1) is TriggerReason.TRACKING_BOUND


def test_error_moving_fires_even_while_an_answer_is_in_flight():
    gen = _gen(threshold=0.05)
    _on_track(gen, 0)
    gen.sent(1, 0)
    assert _on_track(gen, 1 * MS, offset=0.01) is None          # moved less than the threshold
    assert _on_track(gen, 2 * MS, offset=0.2) is TriggerReason.ERROR_BOUND


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
