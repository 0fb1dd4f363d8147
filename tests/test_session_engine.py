"""The offline session engine against the real path: the summaries of lockstep sessions recorded before the
restructuring (tests/fixtures/pre_refactor/), bit for bit, at an ideal link and at 5 ms each way; a live lockstep
session of the current default; the recorder's own records; and the offline sweep engine end to end."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
from edge_lockstep_run import run_live_edge_lockstep
from paper_scheme import PAPER_FLAGS, paper
from test_pre_refactor_equality import as_payload_v2, with_totals

from sea_hil.config.loader import load_config
from sea_hil.controller.edge_events import tracking_record
from sea_hil.offline.session_engine import SessionRecords, run_engine
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import parse_link_spec
from sea_hil.protocol.payloads import PayloadCounters, SetpointPayload, StatePayload, TriggerReason, encode
from sea_hil.recorder.zenoh_tap import zenoh_record
from sea_hil.report.session_summary import session_summary
from sea_hil.report.writer import run_report

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "fixtures" / "pre_refactor"
PAPER_PATH = FIXTURES / "paper_path.toml"     # selects the behaviour the fixtures were recorded with
# every deterministic block of a session summary (the rest is wall-clock timing or the edge's own counters)
COMPARED = ("transmissions", "tracking", "lead_in", "events_by_reason", "inter_event_s", "duration_s",
            "uplink_outside_msgs", "max_abs_voltage_v")


def _cfg(path: Path | None, link: str | None, **extra: dict) -> object:
    ov: dict = {"link": {"seed": 1}, "disturbance": {"seed": 1}, **extra}
    if link:
        ov["link"]["uplink"] = parse_link_spec(link)
        ov["link"]["downlink"] = parse_link_spec(link)
    return load_config(path, ov)


@pytest.mark.parametrize("mode", ["et", "tt"])
@pytest.mark.parametrize("link", [None, "delay=5ms"])
def test_engine_equals_recorded_lockstep_sessions(mode, link):
    fixture = as_payload_v2(json.loads((FIXTURES / f"run_{mode}_{'d5' if link else 'ideal'}.summary.json").read_text()))
    fixture.update({block: with_totals(fixture[block]) for block in ("transmissions", "lead_in")})   # added since
    cfg = _cfg(PAPER_PATH if PAPER_PATH.exists() else None, link)
    got = session_summary(run_engine(cfg, mode).data, mode)
    assert {k: got[k] for k in COMPARED} == {k: fixture[k] for k in COMPARED}


@pytest.mark.slow
def test_engine_equals_a_live_lockstep_session_with_jitter_and_loss(tmp_path):
    """The paper's scheme (trigger at the controller, no compensation) on a short trajectory, ET, 5 ms +- 2 ms
    (normal) and 2 % loss each way (the default scheme: the next test)."""
    cfg_file = tmp_path / "short.toml"
    cfg_file.write_text("[trajectory]\nperiod_s = 2.0\nlead_in_s = 0.3\n", encoding="utf-8")
    spec = "delay=5ms,jitter=2ms,dist=normal,loss=2%"
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--controller", "et",
                           "--cycles", "1", "--seed", "1", "--config", str(cfg_file), *PAPER_FLAGS, "--uplink", spec,
                           "--downlink", spec, "--out", str(tmp_path / "run")], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    live = json.loads((tmp_path / "run" / "summary.json").read_text())
    got = session_summary(run_engine(_cfg(cfg_file, spec, **paper()), "et").data, "et")
    assert live["edge"]["uplink_dropped"] > 0 and live["edge"]["downlink_dropped"] >= 0   # states were lost
    assert {k: got[k] for k in COMPARED} == {k: live[k] for k in COMPARED}


@pytest.mark.slow
def test_engine_equals_a_live_edge_trigger_predict_session_on_a_delayed_lossy_link(tmp_path):
    """Issue 16: the trigger at the edge with the model lookahead and prediction at the controller, live (EVENT_STATE
    up, the edge's tracking records, the controller's predictor on the stamped arrival times) equals the engine with
    the same config bit for bit; short trajectory, 5 ms +- 2 ms (normal) and 2 % loss each way."""
    spec = "delay=5ms,jitter=2ms,dist=normal,loss=2%"
    cfg_file, live = run_live_edge_lockstep(tmp_path, spec)
    cfg = _cfg(cfg_file, spec, trigger={"placement": "edge"}, controller={"compensation": "predict"})
    got = session_summary(run_engine(cfg, "et").data, "et")
    assert live["edge"]["uplink_dropped"] > 0 and live["edge"]["edge_events"] > 0
    assert {k: got[k] for k in COMPARED} == {k: live[k] for k in COMPARED}
    rep = run_report(tmp_path / "run" / "session.mcap", tmp_path / "report")   # the recording reproduces the summary
    assert {k: rep[k] for k in COMPARED} == {k: live[k] for k in COMPARED}


def test_records_are_the_recorders_own():
    keys = Keys.from_config(load_config().zenoh)
    rec = SessionRecords(keys)
    fb = ((0.1, 0.2), (0.3, -0.4), (0.001, -0.002), (0.01, 0.02))
    rec.state(StatePayload(7, 70_000_000, 70_000_000, *fb), 0)
    sp = SetpointPayload(3, 70_000_000, 7, (0.004, -0.001), (0.5, -0.25), TriggerReason.ERROR_BOUND)
    rec.setpoint(sp, 0)
    counters = PayloadCounters()
    state_bytes = encode(StatePayload(7, 70_000_000, 70_000_000, *fb))
    assert rec.messages["/zenoh/state"][0].payload == zenoh_record(keys.state, state_bytes, counters)[1]
    assert rec.messages["/zenoh/setpoint"][0].payload == zenoh_record(keys.setpoint, encode(sp), counters)[1]
    ds = type("DS", (), {"theta_rad": (0.11, 0.19)})()
    record = tracking_record(-5_000_000, 7, fb[0], ds, sp.reason, 3)
    rec.tracking(record, 0)
    assert rec.messages["/tracking"][0].payload == zenoh_record(keys.event, json.dumps(record).encode(), counters)[1]


def test_offline_sweep_runs_the_engine_and_agrees_with_it(tmp_path):
    short = tmp_path / "short.toml"
    # a 1 s gait is too fast for the drive limits derived for the 10 s gait (sea-hil check refuses it): off
    short.write_text("[trajectory]\nperiod_s = 1.0\nlead_in_s = 0.2\n[safety.drive]\nenabled = false\n"
                     "[safety.setpoint]\nenabled = false\n", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "sweep", "--out", str(tmp_path / "sw"), "--config",
                           str(short), "--eta", "0.5", "--r", "0.2", "--delay-ms", "0,5", "--jitter-ms", "1",
                           "--loss", "0.01", "--seed", "2", "--jobs", "2"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / "sw" / "sweep.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["controller"], r["delay_ms"], r["status"]) for r in rows] == [
        ("tt", "0.0", "ok"), ("et", "0.0", "ok"), ("tt", "5.0", "ok"), ("et", "5.0", "ok")]
    et5 = rows[3]
    link = {"delay_s": 0.005, "jitter_s": 0.001, "loss": 0.01}
    cfg = load_config(short, {"link": {"seed": 2, "uplink": link, "downlink": link}, "disturbance": {"seed": 2},
                              "trigger": {"eta": 0.5, "r": 0.2}})
    direct = session_summary(run_engine(cfg, "et").data, "et")
    assert int(et5["downlink_msgs"]) == direct["transmissions"]["downlink_msgs"]
    assert float(et5["max_err_rad"]) == max(direct["tracking"]["max_abs_error_rad"])
    assert (tmp_path / "sw" / "pareto.png").exists() and "engine offline" in proc.stderr
