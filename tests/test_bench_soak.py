"""bench/bench_soak.py's pure parts: RSS growth after the first minute from sampled series, and its records."""
from __future__ import annotations

import json
from pathlib import Path

from bench import bench_soak


def test_growth_after_the_first_minute_and_records() -> None:
    s = bench_soak.Sampler()
    for k in range(300):   # 5 min at 1 Hz: flat "run", "recorder" +1 MB/min after a start-up jump
        t = float(k)
        s.samples["run"].append((t, 200.0, 0.5 * t))
        s.samples["recorder"].append((t, (50.0 if t < 30 else 80.0) + t / 60.0, 0.1 * t))
    g = s.growth()
    assert abs(g["run"]["growth_mb"]) < 1e-9 and abs(g["run"]["slope_mb_per_min"]) < 1e-9
    # median of the last 10 samples (t 290..299) minus the median over [60, 70): 4 minutes at 1 MB/min
    assert abs(g["recorder"]["growth_mb"] - (294.5 - 64.5) / 60.0) < 1e-6
    assert abs(g["recorder"]["slope_mb_per_min"] - 1.0) < 1e-6
    assert abs(g["run"]["cpu_pct"] - 50.0) < 1e-6
    rec = {"can_seq_gaps": 9, "can_rejected": 0, "can_feedback_short": 0, "can_command_short": 0,
           "zenoh_down_dropped": 0, "controller_states_skipped": 5, "recorder_lost": 0, "plant_ticks": 1, "messages": 1}
    rss, can, zen, comp = bench_soak.soak_records(g, rec, 5.0, "ok", 300.0, "python -m bench.bench_soak")
    assert rss["goal_met"] is True and rss["median"] == g["recorder"]["growth_mb"]
    assert can["goal_met"] is True and comp["goal_met"] is True and zen["median"] == 0
    grown = bench_soak.soak_records({**g, "run": {**g["run"], "growth_mb": 6.0}}, rec, 5.0, "ok", 0.0, "x")
    assert grown[0]["goal_met"] is False
    assert bench_soak.soak_records(g, rec, 5.0, "stalled", 0.0, "x")[3]["goal_met"] is False
    assert bench_soak.soak_records(g, {**rec, "can_command_short": 2}, 5.0, "ok", 0.0, "x")[1]["goal_met"] is False


def test_too_short_a_session_has_no_growth_figure() -> None:
    s = bench_soak.Sampler()
    for k in range(50):
        s.samples["run"].append((float(k), 100.0, 0.0))
    g = s.growth()["run"]
    assert g["growth_mb"] != g["growth_mb"]   # NaN: no samples after the first minute


def _event_recording(path: Path, event_seqs: list[int], setpoint_seqs: tuple[int, ...] = (),
                     edge_seq_lost: int = 0, setpoints_sent: int = 0) -> None:
    """A synthetic session file through the recorder's own Zenoh tap: edge-trigger states (EVENT_STATE, header seq =
    the sample number, so it has gaps by design) numbered `event_seqs`, and the edge's final stats counting them."""
    from sea_hil.protocol.payloads import EventStatePayload, SetpointPayload, TriggerReason, encode
    from sea_hil.recorder.writer import SessionRecorder
    from sea_hil.recorder.zenoh_tap import ZenohTap

    tap = ZenohTap()
    with SessionRecorder(path, flush_period_s=None) as rec:
        for k, ev in enumerate(event_seqs):
            sample = 1 + 7 * ev   # every 7th sample published: header seq gaps that are not losses
            data = encode(EventStatePayload(sample, 1000 + k, 10**6 * sample, (0.1, 0.2), (0.0, 0.0), (0.0, 0.0),
                                            (0.0, 0.0), ev, TriggerReason.TIME, 3))
            for r in tap.records("sea/limb1/state", data, 10**18 + k):
                rec.record(r.topic, r.log_time_ns, r.publish_time_ns, r.payload, r.sequence)
        for sp in setpoint_seqs:
            data = encode(SetpointPayload(sp, 5, 1 + 7 * sp, (1e-4, 1e-4), (0.0, 0.0), TriggerReason.TIME))
            for r in tap.records("sea/limb1/setpoint", data, 10**18 + sp):
                rec.record(r.topic, r.log_time_ns, r.publish_time_ns, r.payload, r.sequence)
        stats = [{"node": "edge", "final": True, "t_ns": 1, "uplink_msgs": max(event_seqs), "seq_lost": edge_seq_lost},
                 {"node": "controller", "final": True, "t_ns": 1, "setpoints_sent": setpoints_sent}]
        for st in stats:
            for r in tap.records("sea/limb1/stats", json.dumps(st).encode(), 10**18 + len(event_seqs)):
                rec.record(r.topic, r.log_time_ns, r.publish_time_ns, r.payload, r.sequence)
        rec.close(final_stats={"recorder_dropped_ops": 0})   # as the recorder process closes it


def test_recording_check_counts_a_missing_event_state_and_none_when_complete(tmp_path: Path) -> None:
    complete, holed = tmp_path / "complete.mcap", tmp_path / "holed.mcap"
    _event_recording(complete, list(range(1, 51)))
    _event_recording(holed, [e for e in range(1, 51) if e not in (17, 30, 31)])
    ok = bench_soak.recording_check(complete)
    assert (ok["states_recorded"], ok["states_published"], ok["state_seq_gaps_recorded"]) == (50, 50, 0)
    assert ok["recorder_lost"] == 0 and ok["complete"] and ok["closed_by"] == "close"
    bad = bench_soak.recording_check(holed)
    assert (bad["states_recorded"], bad["state_seq_gaps_recorded"]) == (47, 3)
    assert bad["recorder_lost"] == 3 + 3   # 3 published-vs-recorded + 3 sequence gaps


def test_a_setpoint_the_edge_never_got_either_is_a_network_drop_not_a_recorder_loss(tmp_path: Path) -> None:
    sent = tuple(s for s in range(1, 21) if s != 9)      # setpoint 9 dropped before the host: neither tap got it
    dropped = tmp_path / "dropped.mcap"
    _event_recording(dropped, list(range(1, 11)), sent, edge_seq_lost=1, setpoints_sent=20)
    r = bench_soak.recording_check(dropped)
    assert (r["setpoints_recorded"], r["setpoint_seq_gaps_recorded"], r["zenoh_down_dropped"]) == (19, 1, 1)
    assert r["setpoints_lost_before_host"] == 1 and r["recorder_lost"] == 0
    lost = tmp_path / "lost.mcap"                        # the edge got it, the file does not hold it: a loss
    _event_recording(lost, list(range(1, 11)), sent, edge_seq_lost=0, setpoints_sent=20)
    assert bench_soak.recording_check(lost)["recorder_lost"] == 1 + 1
