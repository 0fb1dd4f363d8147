"""`sea-hil sweep`: grid parsing and expansion, per-point overrides, CSV rows, the Pareto front (pure); the runner
with stand-in point processes (failure isolation); bad arguments; a real 2-point lockstep sweep; Ctrl-C."""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sea_hil.cli import main
from sea_hil.errors import ConfigError
from sea_hil.sweep.csvlog import write_csv
from sea_hil.sweep.grid import (
    CSV_COLUMNS,
    GridPoint,
    LinkCondition,
    csv_row,
    expand_grid,
    pareto_front,
    parse_axis,
    point_command,
    point_overrides,
)
from sea_hil.sweep.output import fronts_by_link, write_outputs
from sea_hil.sweep.runner import SweepOptions, point_config, progress_line, run_sweep

ROOT = Path(__file__).resolve().parents[1]
RUN_SUMMARY = {"transmissions": {"downlink_msgs": 304, "downlink_bytes": 16112, "uplink_msgs": 1001},
               "tracking": {"max_abs_error_rad": [0.0082, 0.0037], "rms_error_rad": [0.0012, 0.0019]},
               "timing": {"latency_us": {"p50": 790.0, "p99": 1700.0}, "latency_samples": 304}}
ET = GridPoint(3, "et", LinkCondition(5.0, 2.0, 0.05), 0.5, 0.2)
TT = GridPoint(2, "tt", LinkCondition(5.0, 2.0, 0.05))


# ---- grid (pure) ----------------------------------------------------------------------------------------------------
def test_parse_axis_accepts_lists():
    assert parse_axis("eta", "0.3, 0.5,0.8") == (0.3, 0.5, 0.8)
    assert parse_axis("loss", "0,1") == (0.0, 1.0)
    assert parse_axis("delay-ms", "0") == (0.0,)


@pytest.mark.parametrize("name,text", [("eta", "0"), ("eta", "-0.1"), ("r", "x"), ("eta", ""), ("eta", "0.3,,0.5"),
                                       ("eta", "nan"), ("delay-ms", "-1"), ("jitter-ms", "inf"), ("loss", "1.5"),
                                       ("r", "0.1,0.1")])
def test_parse_axis_rejects(name, text):
    with pytest.raises(ConfigError, match=f"--{name}"):
        parse_axis(name, text)


def test_expand_grid_one_tt_reference_per_link_condition():
    points = expand_grid((0.3, 0.5), (0.2,), (0.0, 10.0), (0.0,), (0.0, 0.05))
    assert len(points) == 4 * (1 + 2)
    assert [p.index for p in points] == list(range(12))
    assert len({p.name for p in points}) == 12
    links = {p.link for p in points}
    assert len(links) == 4
    for link in links:
        at = [p for p in points if p.link == link]
        assert [p.controller for p in at].count("tt") == 1
        assert {(p.eta, p.r) for p in at if p.controller == "et"} == {(0.3, 0.2), (0.5, 0.2)}
    assert all(p.eta is None and p.r is None for p in points if p.controller == "tt")


def test_point_overrides_and_config(tmp_path):
    ov = point_overrides(ET)
    assert ov["trigger"] == {"eta": 0.5, "r": 0.2}
    for d in ("uplink", "downlink"):
        assert ov["link"][d] == {"delay_s": 0.005, "jitter_s": 0.002, "loss": 0.05}
    assert point_overrides(TT)["trigger"] == {"placement": "controller"}   # TT stays periodic both ways
    assert set(point_overrides(ET, "downlink")["link"]) == {"downlink"}
    with pytest.raises(ConfigError):
        point_overrides(ET, "sideways")
    base = tmp_path / "base.toml"
    base.write_text("[trajectory]\nperiod_s = 3.0\n[link.uplink]\nrate_bps = 1e6\n", encoding="utf-8")
    cfg = point_config(SweepOptions(out=tmp_path, config=base, seed=7), ET)
    assert (cfg.trigger.eta, cfg.trigger.r, cfg.trajectory.period_s) == (0.5, 0.2, 3.0)
    assert (cfg.link.seed, cfg.disturbance.seed) == (7, 7)
    assert (cfg.link.uplink.delay_s, cfg.link.uplink.rate_bps, cfg.link.downlink.loss) == (0.005, 1e6, 0.05)


def test_point_command():
    cmd = point_command(ET, "lockstep", Path("c.toml"), Path("o"), 2, python="py")
    assert cmd[:7] == ["py", "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--no-figures"]
    assert cmd[cmd.index("--controller") + 1] == "et" and cmd[cmd.index("--cycles") + 1] == "2"
    with pytest.raises(ConfigError, match="only the lockstep engine"):
        point_command(TT, "offline", Path("c.toml"), Path("o"), 1)
    with pytest.raises(ConfigError):
        point_command(ET, "realtime", Path("c.toml"), Path("o"), 1)


# ---- rows and Pareto front (pure) -----------------------------------------------------------------------------------
def test_csv_row_from_run_summary():
    row = csv_row(ET, RUN_SUMMARY, cycles=1, seed=3, wall_s=9.1234)
    assert tuple(row) == CSV_COLUMNS
    assert (row["controller"], row["eta"], row["r"], row["delay_ms"], row["jitter_ms"], row["loss"]) == \
        ("et", 0.5, 0.2, 5.0, 2.0, 0.05)
    assert (row["downlink_msgs"], row["downlink_bytes"], row["uplink_msgs"]) == (304, 16112, 1001)
    assert (row["max_err_hip_rad"], row["max_err_knee_rad"], row["max_err_rad"]) == (0.0082, 0.0037, 0.0082)
    assert (row["rms_err_hip_rad"], row["rms_err_knee_rad"], row["rms_err_rad"]) == (0.0012, 0.0019, 0.0019)
    assert (row["latency_p50_us"], row["latency_p99_us"], row["wall_s"], row["status"]) == (790.0, 1700.0, 9.123, "ok")


def test_csv_row_offline_and_failed():
    offline_tx = {"downlink_msgs": 997, "downlink_bytes": 997 * 53, "uplink_msgs": 1000, "uplink_bytes": 88_000}
    off = csv_row(TT, {"transmissions": offline_tx, "tracking": RUN_SUMMARY["tracking"], "timing": {"cpu_s": 0.1}},
                  cycles=1, seed=0, wall_s=1.0)
    assert (off["downlink_msgs"], off["downlink_bytes"], off["latency_p99_us"], off["eta"]) == (997, 52841, "", "")
    bad = csv_row(ET, None, cycles=1, seed=0, wall_s=2.0, status="error", error="exit 2:\n  boom")
    assert (bad["status"], bad["error"], bad["downlink_msgs"], bad["max_err_rad"]) == ("error", "exit 2: boom", "", "")


def test_pareto_front_example():
    xy = [(300, 0.08), (1000, 0.07), (500, 0.09), (300, 0.08), (200, 0.2), (1000, 0.1)]
    assert pareto_front(xy) == [True, True, False, True, True, False]


@given(st.lists(st.tuples(st.integers(0, 20), st.integers(0, 20)), min_size=1, max_size=25))
def test_pareto_front_properties(xy):
    front = pareto_front(xy)
    on = [p for p, f in zip(xy, front, strict=True) if f]
    for p, f in zip(xy, front, strict=True):
        beaten = any(q[0] <= p[0] and q[1] <= p[1] and q != p for q in on)
        assert beaten != f
    assert min(xy) in on and min(xy, key=lambda p: (p[1], p[0])) in on


def test_progress_line():
    line = progress_line(2, 8, 20.0, csv_row(ET, RUN_SUMMARY, cycles=1, seed=0, wall_s=9.0), ET)
    assert line.startswith("[  2/8]") and "ETA    60 s" in line and "304 downlink msgs" in line
    assert "eta=0.5 r=0.2" in line and "loss 0.05" in line


def test_outputs_from_rows(tmp_path):
    rows = [csv_row(TT, {**RUN_SUMMARY, "transmissions": {"downlink_msgs": 1001}}, cycles=1, seed=0, wall_s=1),
            csv_row(ET, RUN_SUMMARY, cycles=1, seed=0, wall_s=1),
            csv_row(GridPoint(4, "et", ET.link, 0.8, 0.2), None, cycles=1, seed=0, wall_s=1, status="error",
                    error="exit status 2: boom")]
    fronts = fronts_by_link(rows)
    key = (5.0, 2.0, 0.05, "")   # delay, jitter, loss, link spec ("": the axes)
    assert list(fronts) == [key] and [f for _, f in fronts[key]] == [False, True]
    write_outputs(tmp_path, rows, "sea-hil sweep ...", 3.0, 2, "lockstep", False)
    write_csv(tmp_path / "sweep.csv", rows)
    with (tmp_path / "sweep.csv").open(encoding="utf-8") as fh:
        got = list(csv.DictReader(fh))
    assert [r["status"] for r in got] == ["ok", "ok", "error"] and got[2]["error"] == "exit status 2: boom"
    assert (tmp_path / "pareto.png").stat().st_size > 10_000
    assert not (tmp_path / "methods.png").exists()    # one scheme: no method comparison to draw
    md = (tmp_path / "sweep.md").read_text(encoding="utf-8")
    assert "ET η=0.5 r=0.2 (304 tx/cycle, 0.0082 rad)" in md and "error: exit status 2: boom" in md


# ---- runner with stand-in point processes ----------------------------------------------------------------------------
def test_failing_point_is_a_row_not_a_crash(tmp_path, monkeypatch):
    def fake(point, mode, cfg_path, out, cycles, python):
        if point.controller == "tt":
            return [python, "-c", "import sys; print('sea-hil run: error: boom'); sys.exit(3)"]
        code = f"import json, pathlib; pathlib.Path({str(out)!r}, 'summary.json').write_text(json.dumps({RUN_SUMMARY!r}))"
        return [python, "-c", code]
    monkeypatch.setattr("sea_hil.sweep.task.point_command", fake)   # the local cluster runs tasks in threads
    lines: list[str] = []
    points = expand_grid((0.5,), (0.2,), (0.0,), (0.0,), (0.0,))
    rows, interrupted = run_sweep(points, SweepOptions(out=tmp_path, mode="lockstep", jobs=2, progress_bar=False),
                                  lines.append)
    assert not interrupted and len(lines) == 2
    assert (rows[0]["status"], rows[0]["error"]) == ("error", "exit status 3: sea-hil run: error: boom")
    assert (rows[1]["status"], rows[1]["downlink_msgs"]) == ("ok", 304)
    assert (tmp_path / "points" / points[1].name / "input.toml").read_text().count("eta = 0.5") == 1


# ---- CLI -------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("extra,msg", [(["--eta", "0,1"], "--eta: 0 out of range"), (["--loss", "2"], "--loss"),
                                       (["--r", "a"], "--r: 'a' is not a number"), (["--jobs", "0"], "--jobs"),
                                       (["--mode", "offline", "--engine", "lockstep"], "old name of --engine"),
                                       (["--config", "/nonexistent.toml"], "config file not found")])
def test_bad_arguments_exit_2_with_one_line(tmp_path, capsys, extra, msg):
    assert main(["sweep", "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sea-hil sweep: error:") and msg in err and "\n" not in err
    assert not (tmp_path / "o" / "points").exists()


def _sweep_cmd(tmp_path: Path, *extra: str) -> list[str]:
    short = tmp_path / "short.toml"
    short.write_text("[trajectory]\nperiod_s = 2.0\n", encoding="utf-8")
    return [sys.executable, "-m", "sea_hil.cli", "sweep", "--out", str(tmp_path / "sw"), "--config", str(short),
            "--eta", "0.5", "--r", "0.2", "--jitter-ms", "0", "--loss", "0", "--seed", "1", "--engine", "lockstep",
            *extra]


def _pids_mentioning(*texts: str) -> list[int]:
    """Processes whose command line contains every one of `texts`."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and entry.name != str(os.getpid()):
            try:
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if all(t.encode() in cmdline for t in texts):
                found.append(int(entry.name))
    return found


def _wait_for(cond, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.slow
def test_ctrl_c_ends_every_point_process(tmp_path):
    cmd = _sweep_cmd(tmp_path, "--delay-ms", "0", "--jobs", "1", "--cycles", "50")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    marker = str(tmp_path / "sw" / "points")
    try:
        controller_up = _wait_for(lambda: bool(_pids_mentioning(marker, "controller")), 60)
        assert controller_up, "the first point's controller process never started"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert "interrupted" in err
    with (tmp_path / "sw" / "sweep.csv").open(encoding="utf-8") as fh:
        assert {r["status"] for r in csv.DictReader(fh)} == {"cancelled"}
    assert _pids_mentioning(marker) == []
