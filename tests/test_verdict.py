"""A verdict on every run (issue 29 parts 1, 2 and 5, sea_hil/verdict/rules.py): real sessions driven into each
state the verdict judges -- a drive fault (the issue's start pose, forced past the input check), an e-stop, late
setpoints, envelope rejections (lockstep), a watchdog trip, driver tick misses, setpoints and states lost outside
the link model (real time: a downlink outage from a link trace, a driver stalled at the clock level, a lossy
transport between edge and controller) -- each gives its reason with its figure and threshold, `--strict` exits 3,
the end-of-run table and `sea-hil report` show it, the live view's final verdict agrees, and a clean session is
`ok`."""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from test_completeness import two_limbs

from sea_hil.cli import main
from sea_hil.config.loader import load_config
from sea_hil.config.verdict import VerdictConfig
from sea_hil.live.verdict import SUMMARY_ONLY
from sea_hil.live.view import LiveView
from sea_hil.protocol.can_frames import EStop
from sea_hil.recorder.meta import CONFIG_ATTACHMENT
from sea_hil.recorder.reader import SessionData, read_session
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.report.console import end_of_run_rows
from sea_hil.report.limbs import META_FLOOR
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary_schema import SUMMARY_SCHEMA
from sea_hil.session.run import RunOptions, run_session
from sea_hil.verdict.edge_blocks import split_edge_stats
from sea_hil.verdict.rules import COUNTER_RULES, verdict, verdict_config_of

pytestmark = pytest.mark.slow
# a 2 s gait: the drive's soft limits (derived for the 10 s gait) are off unless a test needs them
SHORT: dict[str, Any] = {"trajectory": {"period_s": 2.0},
                         "safety": {"drive": {"enabled": False}, "setpoint": {"enabled": False}}}


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _session(tmp: Path, name: str, overrides: dict[str, Any], lockstep: bool = True) -> dict[str, Any]:
    cfg = load_config(overrides=_merge(SHORT, overrides))
    s = run_session(cfg, RunOptions(controller="et", out=tmp / name, lockstep=lockstep, progress=False,
                                    figures=False))
    jsonschema.validate(s, SUMMARY_SCHEMA)
    return s


def _codes(s: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {r["code"]: r for r in s["verdict"]["reasons"]}


def _live_final(data: SessionData, lockstep: bool) -> dict[str, Any]:
    """The live view's final `/live/verdict` of a recording replayed through it in log-time order (what the recorder
    child feeds it), under the recording's own `[verdict]`, host floor and limbs (what `sea-hil run` hands it)."""
    floor = {k: float(v) for k, v in data.metadata.get(META_FLOOR, {}).items()} or None
    limbs = {int(v.split()[0]): name for name, v in data.metadata.get("sea-hil.limbs", {}).items()}
    view = LiveView(bitrate_bps=1_000_000, verdict=verdict_config_of(data.attachments.get(CONFIG_ATTACHMENT)),
                    lockstep=lockstep, floor=floor, limbs=limbs)
    msgs = sorted(((m.log_time_ns, i, topic, m.payload) for topic, ms in data.messages.items()
                   for i, m in enumerate(ms)), key=lambda x: (x[0], x[1]))
    for t_ns, _, topic, payload in msgs:
        view.feed(topic, t_ns, payload)
    (final,) = [m.message for m in view.finish() if m.topic == "/live/verdict"]
    return final


def _assert_live_agrees(s: dict[str, Any], mcap: Path | SessionData) -> None:
    """The live view's final verdict: summary.json's, but for the reasons only summary.json judges."""
    live = _live_final(read_session(mcap) if isinstance(mcap, Path) else mcap, s.get("lockstep", True))
    reasons = [r for r in s["verdict"]["reasons"] if r["code"] not in SUMMARY_ONLY]
    assert live["final"] and live["codes"] == [r["code"] for r in reasons]
    assert live["reasons"] == [r["message"] for r in reasons]
    assert live["status"] == s["verdict"]["status"] or {r["code"] for r in s["verdict"]["reasons"]} & set(SUMMARY_ONLY)


# ---- the case: forced past the input check, the drive faults, the verdict says so -------------------------
@pytest.fixture(scope="module")
def forced(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, str]:
    tmp = tmp_path_factory.mktemp("forced")
    cfg = tmp / "cfg.toml"
    cfg.write_text("[plant]\ninitial_theta_rad = [0.9, 1.3]\n", encoding="utf-8")   # the config
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["run", "--lockstep", "--controller", "et", "--cycles", "1", "--no-figures", "--quiet",
                   "--config", str(cfg), "--out", str(tmp / "out"), "--allow-unsafe-start", "--strict"])
    return tmp / "out", rc, out.getvalue()


def test_forced_start_pose_is_invalid_with_the_fault_time_and_flags(forced: tuple[Path, int, str]) -> None:
    out, rc, table = forced
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    jsonschema.validate(s, SUMMARY_SCHEMA)
    assert s["verdict"]["status"] == "invalid"
    fault = _codes(s)["drive_fault"]
    assert fault["flags"] == ["POSITION_LIMIT"] and fault["cleared"] is False
    assert 0.0 <= fault["t_s"] <= 0.11           # at the first heartbeat: the drive faults at its first sample
    assert fault["in_fault_s"] > 10.0            # latched to the end of the session (10 s cycle + the lead-in)
    assert "needs the user" in fault["message"]
    assert rc == 3                               # --strict
    assert table.index("verdict") < table.index("mode")   # the verdict first, then every reason
    assert "INVALID" in table and "drive_fault" in table and "POSITION_LIMIT" in table
    assert "warnings" in table and "warnings                   │ none" not in table
    _assert_live_agrees({**s, "lockstep": True}, out / "session.mcap")   # the live view judges it so too


def test_the_latch_is_explained_once_in_the_recording(forced: tuple[Path, int, str]) -> None:
    """Part 5: one /log/faults line per latch, with the limit, the measured value and who clears it."""
    data = read_session(forced[0] / "session.mcap")
    lines = [m.payload["message"] for m in data.messages["/log/faults"] if "latched" in m.payload["message"]]
    assert len(lines) == 1, lines
    assert "FAULT POSITION_LIMIT" in lines[0] and "hip angle 0.9" in lines[0]
    assert "above safety.drive.position_max_rad[0] = 0.66 rad" in lines[0] and "needs the user" in lines[0]


def test_without_a_can_tap_the_edges_latch_count_judges(forced: tuple[Path, int, str]) -> None:
    """A recording without a CAN tap (`sea-hil record` without `--can`: no /can/raw) of the faulted drive: the latch
    the edge counted from the heartbeats it received makes the verdict invalid, with the same flags and time; with
    the tap, the heartbeats in the file judge and the edge's count is not added (one reason, not two)."""
    data = read_session(forced[0] / "session.mcap")
    tapped = session_summary(data, "et")
    data.messages.pop("/can/raw")
    untapped = session_summary(data, "et")
    assert [(f["source"], f["flags"]) for f in tapped["drive_faults"]] == [("can", ["POSITION_LIMIT"])]
    assert [(f["source"], f["flags"]) for f in untapped["drive_faults"]] == [("edge", ["POSITION_LIMIT"])]
    assert tapped["edge"]["drive_latches"] == 1 == untapped["edge"]["drive_latches"]
    assert untapped["verdict"]["status"] == "invalid"
    faults = [r for r in untapped["verdict"]["reasons"] if r["severity"] == "invalid"]
    assert [r["code"] for r in faults] == ["drive_fault"] and faults[0]["flags"] == ["POSITION_LIMIT"]
    assert [r["code"] for r in tapped["verdict"]["reasons"] if r["severity"] == "invalid"] == ["drive_fault"]
    edge_t, can_t = untapped["drive_faults"][0]["t_s"], tapped["drive_faults"][0]["t_s"]
    assert abs(edge_t - can_t) <= 0.002, (edge_t, can_t)   # the same heartbeat: the sample clock vs the tap's
    assert untapped["drive_faults"][0]["in_fault_s"] > 10.0 and not untapped["drive_faults"][0]["cleared"]


def test_report_reproduces_the_verdict(forced: tuple[Path, int, str], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = forced[0]
    assert main(["report", str(out / "session.mcap"), "--out", str(tmp_path)]) == 0
    rep = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    run = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert rep["verdict"] == run["verdict"]
    assert "verdict: **invalid**" in (tmp_path / "report.md").read_text(encoding="utf-8")
    table = capsys.readouterr().out   # the end-of-run table, the verdict first
    assert "verdict" in table and "INVALID" in table and "drive_fault" in table
    assert main(["report", str(out / "session.mcap"), "--out", str(tmp_path / "json"), "--json"]) == 0
    captured = capsys.readouterr()   # --json: the summary on stdout, the verdict on stderr
    assert json.loads(captured.out)["verdict"] == run["verdict"]
    assert "sea-hil report: verdict: INVALID" in captured.err


# ---- lockstep: late setpoints, envelope rejections; a clean session is ok ----------------------------------------
def test_late_setpoints_degrade(tmp_path: Path) -> None:
    """Each answer acts 20 ms (uplink + downlink) after its state, the deadline is 15 ms: every one is late."""
    s = _session(tmp_path, "late", {"trigger": {"placement": "controller"}, "controller": {"compensation": "none"},
                                    "link": {"uplink": {"delay_s": 0.01}, "downlink": {"delay_s": 0.01}},
                                    "safety": {"setpoint": {"max_answer_age_s": 0.015}}})
    r = _codes(s)["late_setpoints"]
    assert r["value"] == s["edge"]["late_setpoints"] > 0 and r["threshold"] == 0
    assert s["verdict"]["status"] in ("degraded", "invalid")


def test_envelope_rejections_degrade(tmp_path: Path) -> None:
    """Some setpoints of the 2 s gait ask for more than 0.5 mm of spring deflection (at most 0.57 mm): rejected
    (the paper's scheme)."""
    envelope = {"enabled": True, "deflection_max_m": [0.0005, 0.0005]}
    s = _session(tmp_path, "envelope", {"trigger": {"placement": "controller"}, "controller": {"compensation": "none"},
                                        "safety": {"setpoint": envelope}})
    r = _codes(s)["envelope_rejections"]
    assert r["value"] == s["edge"]["setpoints_out_of_envelope"] > 0
    assert "safety.setpoint" in r["message"]
    _assert_live_agrees(s, tmp_path / "envelope" / "session.mcap")


def _estop_at(frames: int) -> Any:
    """A session hook: the drive receives an e-stop frame (its DBC `ESTOP`, encoded by the plant's own codec) after
    its `frames`-th received frame, through its receive path, as if pressed on the bus."""
    def hook(plant: Any, edge: Any, proc: Any) -> None:
        on_message, seen = plant._on_message, [0]
        estop = plant.codec.encode(EStop(next(iter(plant.drivers))))

        def pressed(msg: Any, now_ns: int) -> None:
            on_message(msg, now_ns)
            seen[0] += 1
            if seen[0] == frames:
                on_message(estop, now_ns)
        plant._on_message = pressed
    return hook


def test_an_estop_is_invalid(tmp_path: Path) -> None:
    """An e-stop (lockstep): the drive latches ESTOP to the end of the session, the verdict is invalid with the
    latch's time (the heartbeat after the frame: 100 ms resolution) and who clears it, the table shows it."""
    cfg = load_config(overrides=SHORT)
    s = run_session(cfg, RunOptions(controller="et", out=tmp_path / "estop", lockstep=True, progress=False,
                                    figures=False, on_nodes=_estop_at(300)))
    jsonschema.validate(s, SUMMARY_SCHEMA)
    assert s["verdict"]["status"] == "invalid"
    r = _codes(s)["estop"]
    assert r["severity"] == "invalid" and r["state"] == "ESTOP" and "ESTOP" in r["flags"] and not r["cleared"]
    assert 0 < r["t_s"] < 1.0 and r["in_fault_s"] > s["duration_s"] - 1.0   # latched to the end
    assert "latched ESTOP" in r["message"] and "needs the user" in r["message"]
    rows = end_of_run_rows(s)
    assert rows[0][0] == "verdict" and rows[0][1].startswith("INVALID")
    assert ("  invalid: estop", r["message"]) in rows
    _assert_live_agrees(s, tmp_path / "estop" / "session.mcap")


def test_a_clean_lockstep_session_is_ok(tmp_path: Path) -> None:
    s = _session(tmp_path, "clean", {})
    assert s["verdict"] == {"status": "ok", "reasons": []}, s["verdict"]
    assert s["drive_faults"] == [] and s["recording"]["lost"] == 0


# ---- real time: a watchdog trip (downlink outage) and tick misses (a stalled driver) -----------------------------
@pytest.fixture(scope="module")
def realtime(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A real-time session whose downlink loses everything for 0.8 s every 4 s (a link trace): the edge stops
    commanding once its setpoint is stale, the drive's watchdog trips, the edge clears it when setpoints return; and
    whose driver stalls 20 ms every 100th tick at the clock level (its step takes that long), so it misses deadlines
    far beyond the host's floor; whose transport loses every 25th setpoint and whose edge is starved for 30 ms every
    100th sample (`_lossy_transport`)."""
    from plant_emulator_stall import stalled_driver  # tests/plant_emulator_stall.py
    tmp = tmp_path_factory.mktemp("realtime")
    trace = tmp / "outage.csv"
    # looped every 4 s (span 3 s + median gap 1 s): lost from 1.0 to 1.8 s of each loop, longer than the edge's
    # setpoint timeout (2 x max_inter_event_s = 0.5 s) + the watchdog (0.1 s); the 5 s cycle holds a whole outage
    # wherever the controller's start (its child process's start-up time) puts it
    trace.write_text("t_s,delay_s,lost\n0.0,0,0\n1.0,0,1\n1.8,0,0\n3.0,0,0\n", encoding="utf-8")
    cfg = load_config(overrides=_merge(SHORT, {
        "trajectory": {"period_s": 5.0}, "trigger": {"placement": "controller"},
        "controller": {"compensation": "none"}, "link": {"downlink": {"trace_path": str(trace)}},
        "verdict": {"floor_measure_s": 0.2}}))
    with stalled_driver(every=100, stall_s=0.02):
        s = run_session(cfg, RunOptions(controller="et", out=tmp / "out", lockstep=False, progress=False,
                                        figures=False, on_nodes=_lossy_transport))
    jsonschema.validate(s, SUMMARY_SCHEMA)
    return {"summary": s, "out": tmp / "out"}


STATES_DROPPED: list[int] = [0]   # states `_lossy_transport` lost after the uplink model released them


def _lossy_transport(plant: Any, edge: Any, proc: Any) -> None:
    """The transport between controller and edge loses every 25th setpoint payload before the edge sees it and every
    40th state after the uplink model released it (both outside the link model, which runs inside the edge): what a
    lossy Zenoh path would do."""
    sink = edge.core.publisher.uplink._pub   # what the uplink emulator releases goes to its `put` (the publisher)
    put, states = sink.put, [0]

    def lossy_up(data: bytes) -> Any:
        states[0] += 1
        if states[0] % 40 == 0:
            STATES_DROPPED[0] += 1
            return None
        return put(data)
    sink.put = lossy_up
    submit, calls = edge.core.intake.submit, [0]

    def lossy(data: bytes, *args: Any) -> bool:
        calls[0] += 1
        return False if calls[0] % 25 == 0 else bool(submit(data, *args))
    edge.core.intake.submit = lossy
    on_feedback, samples = edge._on_feedback, [0]

    def starved(fb: Any, rx_ns: int) -> None:   # the edge starved for 30 ms every 100th sample: a backlog
        samples[0] += 1
        if samples[0] % 100 == 0:
            time.sleep(0.03)
        on_feedback(fb, rx_ns)
    edge._on_feedback = starved


def test_watchdog_trip_is_invalid_and_cleared_by_the_edge(realtime: dict[str, Any]) -> None:
    s = realtime["summary"]
    trip = _codes(s)["watchdog_trip"]
    assert "WATCHDOG" in trip["flags"] and s["verdict"]["status"] == "invalid"
    assert trip["cleared"] is True and 0 < trip["in_fault_s"] < 2.0
    assert "the edge clears it" in trip["message"]
    data = read_session(realtime["out"] / "session.mcap")
    lines = [m.payload["message"] for m in data.messages["/log/faults"] if "latched" in m.payload["message"]]
    assert any("WATCHDOG" in ln and "the edge clears it" in ln for ln in lines), lines


def test_setpoints_lost_beyond_the_link_model_degrade(realtime: dict[str, Any]) -> None:
    s = realtime["summary"]
    r = _codes(s)["lost_setpoints"]
    assert r["value"] == s["edge"]["seq_lost"] > 0 and r["threshold"] == 0
    assert s["edge"]["downlink_dropped"] > 0   # the model's own drops (the outage) are not in seq_lost


def test_states_lost_beyond_the_uplink_model_degrade(realtime: dict[str, Any]) -> None:
    """Every 40th state lost between the edge and the controller, after the uplink model (`_lossy_transport`): the
    controller's stream-seq gaps beyond the model's own drops (`link_losses.uplink_beyond_model`) degrade the run; the
    table lists the reason and the count."""
    s = realtime["summary"]
    r = _codes(s)["lost_states"]
    beyond = s["link_losses"]["uplink_beyond_model"]
    # the controller counts gaps between the first and the last state it received: not the drops before or after
    assert r["value"] == beyond > 0 and r["threshold"] == 0 and beyond <= STATES_DROPPED[0]
    assert "beyond the uplink model" in r["message"]
    rows = dict(end_of_run_rows(s))
    assert rows["  degraded: lost_states"] == r["message"]
    assert f"states lost beyond the uplink model: {beyond}" in rows["warnings"]


def test_the_live_view_judges_the_real_time_session_as_summary_json(realtime: dict[str, Any]) -> None:
    _assert_live_agrees(realtime["summary"], realtime["out"] / "session.mcap")


def test_late_samples_degrade(realtime: dict[str, Any]) -> None:
    """The starved edge works through a backlog: the samples received more than max_sample_age_s before it got to
    them go unanswered (late_samples), above 1 % of the samples."""
    s = realtime["summary"]
    r = _codes(s)["late_samples"]
    assert r["count"] == s["edge"]["late_samples"]
    assert r["value"] == pytest.approx(100.0 * s["edge"]["late_samples"] / s["edge"]["feedback_samples"], abs=1e-3)
    assert r["value"] > r["threshold"] == 1.0


def test_tick_misses_beyond_the_floor_degrade(realtime: dict[str, Any]) -> None:
    s = realtime["summary"]
    drv = s["timing"]["driver"]
    assert drv["floor"]["ticks"] > 0 and drv["floor"]["duration_s"] == 0.2
    r = _codes(s)["tick_misses"]
    assert r["value"] == pytest.approx(100.0 * drv["tick_misses"] / drv["ticks"], abs=1e-3)
    assert r["threshold"] == pytest.approx(0.1 + 3.0 * drv["floor"]["miss_pct"], abs=1e-3)
    assert r["value"] > r["threshold"] and "floor" in r["message"]


# ---- the rules themselves (no session): every counter rule, the link-loss and rejection rules --------------------
def test_every_counter_rule_names_a_threshold_and_degrades_above_it() -> None:
    cfg = VerdictConfig()
    for rule in COUNTER_RULES:
        assert hasattr(cfg, rule.threshold), rule
    base = {"lockstep": False, "edge": {"feedback_samples": 1000, "commands_sent": 1000}, "drive_faults": []}
    assert verdict(base)["status"] == "ok"
    for path, code in ((("link_losses", "uplink_beyond_model"), "lost_states"), (("edge", "seq_lost"),
                       "lost_setpoints"), (("edge", "epoch_foreign"), "rejections"),
                       (("recording", "lost"), "recording_losses")):
        s = json.loads(json.dumps(base))
        s.setdefault(path[0], {})[path[1]] = 3
        v = verdict(s)
        assert v["status"] == "degraded" and [r["code"] for r in v["reasons"]] == [code], v
        assert verdict(s, VerdictConfig(**{next(r.threshold for r in COUNTER_RULES if r.code == code): 3}))[
            "status"] == "ok"


def test_every_limbs_link_losses_are_judged() -> None:
    """Two limbs (lockstep, the synthetic recording): only limb2's controller saw gaps in its state stream (4 states,
    1 of them the uplink model's own drop at limb2's edge). summary.json's top-level `link_losses` is limb1's (the
    1-limb layout), each limb entry has its own, and the verdict (and the live view's) names limb2."""
    data = two_limbs(edge2={"uplink_dropped": 1}, controller2={"state_seq_lost": 4})
    s = session_summary(data, "et")
    jsonschema.validate(s, SUMMARY_SCHEMA)
    assert s["link_losses"] == {"uplink_beyond_model": 0}
    assert [e["link_losses"]["uplink_beyond_model"] for e in s["limbs"]] == [0, 3]
    reasons = [(r["code"], r.get("limb"), r["value"]) for r in s["verdict"]["reasons"]]
    assert reasons == [("lost_states", "limb2", 3)], s["verdict"]
    assert "limb2: states lost beyond the uplink model: 3" in dict(end_of_run_rows(s))["warnings"]
    _assert_live_agrees(s, two_limbs(edge2={"uplink_dropped": 1}, controller2={"state_seq_lost": 4}))


def test_every_limbs_edge_counters_are_judged() -> None:
    """Two limbs (a synthetic recording, tests/test_completeness.py): limb2's edge lost 3 setpoints and rejected 2
    out of the envelope, limb1's nothing; the top-level `edge` block is limb1's, yet the verdict names limb2."""
    s = session_summary(two_limbs(edge2={"seq_lost": 3, "setpoints_out_of_envelope": 2}), "et")
    jsonschema.validate(s, SUMMARY_SCHEMA)
    assert "seq_lost" not in s["edge"] and [e["edge"].get("seq_lost") for e in s["limbs"]] == [None, 3]
    reasons = {(r["code"], r.get("limb")): r for r in s["verdict"]["reasons"]}
    assert set(reasons) == {("lost_setpoints", "limb2"), ("envelope_rejections", "limb2")}, s["verdict"]
    assert reasons[("lost_setpoints", "limb2")]["value"] == 3
    assert reasons[("lost_setpoints", "limb2")]["message"].startswith("limb2: ")
    one = session_summary(two_limbs(edge1={"seq_lost": 1}), "et")   # limb1's own counter: named too
    assert [(r["code"], r.get("limb")) for r in one["verdict"]["reasons"]] == [("lost_setpoints", "limb1")]
    _assert_live_agrees(s, two_limbs(edge2={"seq_lost": 3, "setpoints_out_of_envelope": 2}))   # live: the same


@pytest.mark.parametrize("table,key", [("late_setpoints_max = -1", "verdict.late_setpoints_max"),
                                       ("lost_setpoint_max = 3", "verdict.lost_setpoint_max"),   # a typo
                                       ("envelope_rejections_max = 'a few'", "verdict.envelope_rejections_max")])
def test_a_bad_verdict_table_in_the_recording_is_an_error(table: str, key: str, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """`report` of a recording whose attached config.toml has a bad [verdict] table: exit 2, one line naming the key
    (it judged under the defaults without a word: a verdict the session's thresholds did not give)."""
    path = tmp_path / "bad.mcap"
    with SessionRecorder(path) as rec:
        rec.add_attachment("config.toml", f"[verdict]\n{table}\n".encode())
    assert main(["report", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad [verdict] table" in err[0] and key in err[0], err
    with SessionRecorder(tmp_path / "garbled.mcap") as rec:
        rec.add_attachment("config.toml", b"[verdict\n")
    assert main(["report", str(tmp_path / "garbled.mcap"), "--out", str(tmp_path / "out2")]) == 2
    assert "config.toml cannot be read" in capsys.readouterr().err


def test_lockstep_has_no_tick_deadlines() -> None:
    s = {"lockstep": True, "timing": {"driver": {"ticks": 100, "tick_misses": 50}}}
    assert verdict(s)["status"] == "ok"
    assert verdict({**s, "lockstep": False})["reasons"][0]["code"] == "tick_misses"


def _cia402_realtime(misses: int, floor_pct: float) -> dict[str, Any]:
    """A real-time cia402 summary as session_summary lays it out: SYNCs sent under `edge`, missed periods (wall-time
    derived) under `timing.edge`, the host's floor under `timing.driver`."""
    det, timing = split_edge_stats({"cia402_syncs": 10_000 - misses, "cia402_sync_misses": misses})
    return {"lockstep": False, "edge": det, "timing": {"edge": timing, "driver": {
        "ticks": 10_000, "tick_misses": 0, "floor": {"ticks": 500, "misses": 0, "miss_pct": floor_pct,
                                                    "lateness_us_p99": 80.0, "duration_s": 0.5}}}}


def test_cia402_sync_misses_are_judged_like_tick_misses_against_the_host_floor() -> None:
    """The cia402 profile's SYNC producer (the edge) misses periods: degraded above sync_miss_max_pct + factor x the
    host's floor, of the periods due (SYNCs sent + missed); shown in the end-of-run table below the threshold too;
    nothing in lockstep."""
    s = _cia402_realtime(100, 0.2)                       # 1 % of the periods, above 0.1 + 3 x 0.2 = 0.7 %
    assert "cia402_sync_misses" in s["timing"]["edge"] and "cia402_syncs" in s["edge"]
    r = {x["code"]: x for x in verdict(s)["reasons"]}["sync_misses"]
    assert r["value"] == pytest.approx(1.0) and r["threshold"] == pytest.approx(0.7) and r["floor_pct"] == 0.2
    assert "100 of 10000 SYNC periods" in r["message"] and "sync_miss_floor_factor" in r["message"]
    assert verdict(_cia402_realtime(100, 0.4))["status"] == "ok"                    # 1 % <= 0.1 + 3 x 0.4
    assert verdict(s, VerdictConfig(sync_miss_max_pct=1.0))["status"] == "ok"
    assert verdict({**s, "lockstep": True})["status"] == "ok"
    assert verdict(_cia402_realtime(0, 0.0))["status"] == "ok"
    assert "SYNC misses: 3 of 10000 periods" in dict(end_of_run_rows(_cia402_realtime(3, 0.0)))["warnings"]
    assert "SYNC" not in dict(end_of_run_rows(_cia402_realtime(0, 0.0)))["warnings"]


def test_strict_simulate_exits_3_on_saturation(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[trajectory]\nperiod_s = 1.0\n[plant]\nvoltage_limit_v = 2.0\n[safety.drive]\nenabled = false\n"
                   "[safety.setpoint]\nenabled = false\n", encoding="utf-8")
    t0 = time.monotonic()
    assert main(["simulate", "--config", str(cfg), "--out", str(tmp_path / "o"), "--strict", "--json"]) == 3
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert _codes(s)["saturated_steps"]["value"] > 1.0
    assert time.monotonic() - t0 < 120


def test_a_latch_is_explained_once_with_limit_value_and_policy() -> None:
    """Part 5, the pure core the edge and the recorder share (sea_hil/fault_explain.py)."""
    from sea_hil.fault_explain import LatchWatch
    from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat
    cfg = load_config()
    watch = LatchWatch(cfg.safety.drive, (cfg.plant.k1_n_per_m, cfg.plant.k2_n_per_m))

    class Fb:
        theta_rad, omega_rad_s, delta_m = (0.2, 1.35), (0.0, -2.5), (0.0, 0.0)

    def hb(state: DriverState, flags: ErrorFlags) -> Heartbeat:
        return Heartbeat(1, state, flags, 0, 0, 0)
    assert watch.on_heartbeat(hb(DriverState.RUNNING, ErrorFlags(0)), Fb()) is None
    line = watch.on_heartbeat(hb(DriverState.FAULT, ErrorFlags.POSITION_LIMIT), Fb())
    assert line is not None and "knee angle 1.35 rad above safety.drive.position_max_rad[1] = 1.3 rad" in line
    assert "needs the user" in line and "hip angle" not in line
    assert watch.on_heartbeat(hb(DriverState.FAULT, ErrorFlags.POSITION_LIMIT), Fb()) is None      # once
    more = watch.on_heartbeat(hb(DriverState.FAULT, ErrorFlags.POSITION_LIMIT | ErrorFlags.VELOCITY_LIMIT), Fb())
    assert more is not None and "knee velocity -2.5 rad/s below -safety.drive.velocity_max_rad_s[1] = -2 rad/s" in more
    assert watch.on_heartbeat(hb(DriverState.INIT, ErrorFlags(0))) is None                          # cleared
    wd = watch.on_heartbeat(hb(DriverState.FAULT, ErrorFlags.WATCHDOG))
    assert wd is not None and "the edge clears it" in wd and "can.watchdog_timeout_s" in wd


def test_strict_sweep_fails_at_the_end_with_the_points(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 2 V limit saturates the inner loop at every point (offline engine): the sweep runs them all, then --strict
    lists each point that is not ok and exits 3; without --strict it exits 0."""
    cfg = tmp_path / "c.toml"
    cfg.write_text("[trajectory]\nperiod_s = 1.0\n[plant]\nvoltage_limit_v = 2.0\n[safety.drive]\nenabled = false\n"
                   "[safety.setpoint]\nenabled = false\n", encoding="utf-8")
    argv = ["sweep", "--config", str(cfg), "--eta", "0.5", "--r", "0.2", "--delay-ms", "0", "--jitter-ms", "0",
            "--loss", "0", "--seed", "1", "--jobs", "1"]
    assert main([*argv, "--out", str(tmp_path / "a"), "--strict"]) == 3
    err = capsys.readouterr().err
    assert "sweep --strict: 2 of 2 points not ok" in err and "saturated_steps" in err
    rows = (tmp_path / "a" / "sweep.csv").read_text(encoding="utf-8")
    assert "degraded" in rows
    assert main([*argv, "--out", str(tmp_path / "b")]) == 0
