"""CAN FD and the bus-timing model in whole lockstep sessions (short trajectory): an FD session equals the offline
session engine quantising like FD; the recording holds FD frames the DBC decodes; with `emulate_bitrate` the
queueing per CAN id is the arbitration's, in simulated time."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import run_engine
from sea_hil.recorder.reader import read_session
from sea_hil.report.session_summary import session_summary

ROOT = Path(__file__).resolve().parents[1]
COMPARED = ("transmissions", "tracking", "lead_in", "events_by_reason", "inter_event_s", "duration_s",
            "uplink_outside_msgs", "max_abs_voltage_v")
SHORT = "[trajectory]\nperiod_s = 2.0\nlead_in_s = 0.3\n"


def _run(tmp_path: Path, name: str, can_toml: str) -> tuple[Path, dict]:
    cfg_file = tmp_path / f"{name}.toml"
    cfg_file.write_text(SHORT + "[can]\n" + can_toml, encoding="utf-8")
    out = tmp_path / name
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--controller", "et",
                           "--cycles", "1", "--seed", "1", "--config", str(cfg_file), "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    return cfg_file, json.loads((out / "summary.json").read_text())


@pytest.mark.slow
def test_fd_lockstep_session_equals_the_offline_engine(tmp_path: Path) -> None:
    cfg_file, live = _run(tmp_path, "fd", "fd = true\n")
    cfg = load_config(cfg_file, {"link": {"seed": 1}, "disturbance": {"seed": 1}})
    got = session_summary(run_engine(cfg, "et").data, "et")
    assert {k: got[k] for k in COMPARED} == {k: live[k] for k in COMPARED}
    classic = session_summary(run_engine(load_config(cfg_file, {"can": {"fd": False}, "link": {"seed": 1},
                                                                 "disturbance": {"seed": 1}}), "et").data, "et")
    assert classic["tracking"] != live["tracking"]     # FD's finer feedback is a different (engine-checked) path
    data = read_session(tmp_path / "fd" / "session.mcap")
    db = cantools.database.load_file(ROOT / "protocol" / "sea.dbc")   # the DBC holds node 1's ids
    raw = [m.payload for m in data.messages["/can/raw"]]
    fd_frames = [p for p in raw if p.get("is_fd")]
    assert {p["can_id"] for p in fd_frames} == {0x028, 0x02A}            # VOLTAGE_CMD_FD, FEEDBACK_FD of node 1
    assert not [p for p in raw if p["can_id"] in (0x021, 0x023, 0x024, 0x025)]   # no classic feedback/voltage
    fb = next(p for p in fd_frames if p["can_id"] == 0x02A)
    assert db.decode_message(fb["can_id"], bytes.fromhex(fb["data_hex"]))["t_us"] >= 0
    rec = next(m.payload for m in data.messages["/can/feedback"] if "omega2_rad_s" in m.payload)
    assert {"theta1_rad", "delta2_m", "nut_vel1_m_s"} <= set(rec)       # the whole sample in one record


@pytest.mark.slow
def test_emulated_bitrate_lockstep_queues_by_priority(tmp_path: Path) -> None:
    _, s = _run(tmp_path, "emu", "emulate_bitrate = true\n")
    bus = s["timing"]["can_bus"]["virtual:sea-hil"]
    per_id = {e["can_id"]: e for e in bus["per_id"]}
    # each sample: FEEDBACK_ANGLE, _JOINT1, _JOINT2 (135 us each) back to back from the sample time, then the
    # edge's VOLTAGE_CMD (105 us); a heartbeat ready at the sample time waits for all four
    assert {k: per_id[k]["latency_us"]["max"] for k in (0x021, 0x023, 0x024, 0x025, 0x027)} == pytest.approx(
        {0x021: 105.0, 0x023: 135.0, 0x024: 270.0, 0x025: 405.0, 0x027: 645.0}, rel=0.01)
    assert per_id[0x025]["queue_us"]["p50"] == pytest.approx(270.0, rel=0.01)
    assert bus["load_pct"] == pytest.approx(51.1, abs=0.1)
    assert s["timing"]["edge"]["can_025_queue_us_p99"] == per_id[0x025]["queue_us"]["p99"]    # and in /stats
