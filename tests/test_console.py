"""End-of-run table and progress display of `sea-hil run` / `simulate` (sea_hil/report/console.py)."""
from __future__ import annotations

import io
import json
from pathlib import Path

from sea_hil.cli import main
from sea_hil.report.console import ProgressSample, SessionProgress, end_of_run_rows, print_end_of_run
from sea_hil.verdict.summary_fields import field

RUN = {"controller": "et", "lockstep": False, "inner": "edge", "duration_s": 10.0,
       "lead_in": {"duration_s": 0.5}, "transmissions": {"uplink_msgs": 1001, "downlink_msgs": 250,
                                                          "uplink_bytes": 88088, "downlink_bytes": 13250},
       "tracking": {"max_abs_error_rad": [0.004, 0.012], "rms_error_rad": [0.002, 0.006]},
       "latency_us": {"p50": 700.0, "p99": 2500.0}, "wall_s": 11.2,
       "edge": {"loop_overruns": 3, "uplink_dropped": 0, "saturated_steps": 12}}


def test_run_table_has_mode_messages_ratio_errors_latency_warnings_and_files(tmp_path: Path):
    rows = dict(end_of_run_rows(RUN, [tmp_path / "session.mcap"]))
    assert rows["mode"] == "real time, ET-SMC, inner loop on edge"
    assert rows["messages up / down / total"] == "1001 / 250 / 1251"
    assert rows["ratio to TT"].startswith("0.250")                     # TT answers each of the 1001 states
    assert rows["bytes up / down / total"] == "88088 / 13250 / 101338"
    assert rows["total ratio to TT"] == "0.625 (1251 / 2002 messages)"  # TT: a state up, a setpoint down per sample
    assert rows["error knee max / RMS"] == "0.0120 / 0.0060 rad"
    assert rows["latency p50 / p99"] == "0.70 / 2.50 ms"
    assert "3 edge loop overruns" in rows["warnings"] and "saturated: 12" in rows["warnings"]
    assert rows["files"].endswith("session.mcap")


def test_timing_fields_are_found_under_timing_too():
    moved = {k: v for k, v in RUN.items() if k not in ("latency_us", "wall_s", "edge")}
    moved["timing"] = {"latency_us": RUN["latency_us"], "wall_s": 11.2, "edge": RUN["edge"]}
    assert end_of_run_rows(moved) == end_of_run_rows(RUN)
    assert field(moved, "latency_us", "p99") == 2500.0 and field(moved, "nothing", default=7) == 7


def test_lockstep_has_no_deadline_misses_and_simulate_uses_the_sample_count():
    rows = dict(end_of_run_rows({**RUN, "lockstep": True}))
    assert "deadline" not in rows["warnings"]
    tx = {"uplink_msgs": 200, "downlink_msgs": 200, "uplink_bytes": 17600, "downlink_bytes": 10600}
    sim = dict(end_of_run_rows({"controller": "tt", "duration_s": 2.0, "transmissions": tx, "timing": {"cpu_s": 0.7},
                                "tracking": RUN["tracking"], "saturated_steps": 0}, command="simulate",
                               tt_msgs=200))
    assert sim["messages up / down / total"] == "200 / 200 / 400" and sim["ratio to TT"].startswith("1.000")
    assert sim["warnings"] == "none" and "latency p50 / p99" not in sim


def test_table_prints_plain_off_a_terminal():
    out = io.StringIO()
    print_end_of_run(RUN, stream=out)
    assert "\x1b[" not in out.getvalue() and "1001 / 250 / 1251" in out.getvalue()


def test_progress_is_plain_lines_off_a_terminal_and_a_bar_on_one():
    sample = ProgressSample(3.4, 0.82, 0.5, 2.0, 1, 78, 82, 782.0)
    plain = io.StringIO()
    with SessionProgress(plain) as p:
        p(sample)
        p("a message")
    assert plain.getvalue().splitlines() == [str(sample), "a message"]
    assert "sim   0.82/2.50 s  cycle 1/1" in str(sample)
    tty = io.StringIO()
    with SessionProgress(tty, terminal=True) as p:
        p(sample)
        p(sample._replace(sim_s=2.4, setpoints=240))
    assert "\x1b[" in tty.getvalue() and "setpoints 240" in tty.getvalue()


def test_simulate_prints_the_table_or_json(tmp_path: Path, capsys, monkeypatch):
    cfg = tmp_path / "short.toml"
    cfg.write_text("[trajectory]\nperiod_s = 0.3\n", encoding="utf-8")
    assert main(["simulate", "--controller", "tt", "--config", str(cfg), "--out", str(tmp_path / "a")]) == 0
    table = capsys.readouterr().out
    assert "ratio to TT" in table and "1.000" in table and "summary.json" in table
    assert main(["simulate", "--controller", "tt", "--config", str(cfg), "--out", str(tmp_path / "b"),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["transmissions"]["downlink_msgs"] == 30
