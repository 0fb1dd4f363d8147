"""`sea-hil sweep` on Dask: the same lockstep results through an external scheduler with two worker processes as on
the embedded local cluster; `--resume` after a killed sweep recomputes only the unfinished points; sweep.csv holds
every finished point while the sweep is still running; seeds as an axis."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from sea_hil.sweep.csvlog import read_rows
from sea_hil.sweep.grid import expand_grid, seed_axis
from sea_hil.sweep.runner import SweepOptions, run_sweep
from sea_hil.sweep.seeds import ci95_half_width, fold_seeds

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
DETERMINISTIC = ("point", "controller", "eta", "r", "delay_ms", "jitter_ms", "loss", "cycles", "seed",
                 "downlink_msgs", "downlink_bytes", "uplink_msgs", "max_err_hip_rad", "max_err_knee_rad",
                 "rms_err_hip_rad", "rms_err_knee_rad", "status", "config_sha256")
SUMMARY = {"transmissions": {"downlink_msgs": 30, "downlink_bytes": 1590, "uplink_msgs": 100},
           "tracking": {"max_abs_error_rad": [0.002, 0.004], "rms_error_rad": [0.001, 0.002]}}


def _wait_for(cond, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _end(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _short_config(tmp_path: Path) -> Path:
    cfg = tmp_path / "short.toml"
    # a 1 s gait is too fast for the drive limits derived for the 10 s gait (sea-hil check refuses it): off
    cfg.write_text("[trajectory]\nperiod_s = 1.0\nlead_in_s = 0.2\n[safety.drive]\nenabled = false\n"
                   "[safety.setpoint]\nenabled = false\n", encoding="utf-8")
    return cfg


def _sweep(tmp_path: Path, out: str, *extra: str) -> tuple[list[dict[str, str]], str]:
    cmd = [sys.executable, "-m", "sea_hil.cli", "sweep", "--out", str(tmp_path / out), "--config",
           str(_short_config(tmp_path)), "--eta", "0.5", "--r", "0.2", "--delay-ms", "5", "--seed", "3", "--engine", "lockstep", *extra]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / out / "sweep.csv").open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh)), proc.stderr


def _check_local_outputs(out: Path, rows: list[dict[str, str]], stderr: str) -> None:
    """The local sweep's CSV agrees with each point's summary.json; figure, markdown and progress lines written."""
    assert [(r["controller"], r["status"]) for r in rows] == [("tt", "ok"), ("et", "ok")]
    for r in rows:
        summary = json.loads((out / "points" / r["point"] / "summary.json").read_text())
        assert int(r["downlink_msgs"]) == summary["transmissions"]["downlink_msgs"] > 0
        assert float(r["max_err_rad"]) == max(summary["tracking"]["max_abs_error_rad"])
        assert float(r["latency_p99_us"]) > 0
    link = tomllib.loads((out / "points" / rows[1]["point"] / "config.toml").read_text())["link"]
    assert (link["downlink"]["delay_s"], link["uplink"]["delay_s"]) == (0.005, 0.005)   # default --link both
    assert (out / "pareto.png").stat().st_size > 10_000 and "## Pareto front" in (out / "sweep.md").read_text()
    assert stderr.count("ETA") == 2          # one plain progress line per point (stderr is not a terminal)


@pytest.mark.slow
def test_two_point_sweep_on_an_external_scheduler_with_two_workers_equals_the_local_one(tmp_path):
    sched_file = tmp_path / "scheduler.json"
    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--scheduler-file", str(sched_file)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_for(lambda: sched_file.exists() and sched_file.stat().st_size > 0, 60, "the scheduler file")
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen([str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                           "--no-dashboard", "--host", "127.0.0.1"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        remote, _ = _sweep(tmp_path, "remote", "--scheduler", address)
    finally:
        _end(procs)
    local, stderr = _sweep(tmp_path, "local", "--jobs", "2")
    _check_local_outputs(tmp_path / "local", local, stderr)
    assert [r["status"] for r in remote] == ["ok", "ok"]
    assert [{k: r[k] for k in DETERMINISTIC} for r in remote] == [{k: r[k] for k in DETERMINISTIC} for r in local]
    assert all(p.poll() is not None for p in procs)


def _fake_sweep_script(tmp_path: Path, out: Path) -> Path:
    """A sweep process whose points 0 and 1 finish at once and whose points 2 and 3 hang (stand-ins)."""
    script = tmp_path / "fake_sweep.py"
    script.write_text(f"""
import json, sys
from pathlib import Path
import sea_hil.sweep.task as task
from sea_hil.sweep.grid import expand_grid
from sea_hil.sweep.runner import SweepOptions, run_sweep

def fake(point, mode, cfg_path, out, cycles, python):
    if point.index >= 2:
        return [python, "-c", "import time; time.sleep(600)  # sea-hil-hanging-point"]
    return [python, "-c", f"import pathlib; pathlib.Path({{str(out)!r}}, 'summary.json').write_text({{json.dumps({SUMMARY!r})!r}})"]

task.point_command = fake
points = expand_grid((0.3, 0.5, 0.8), (0.2,), (0.0,), (0.0,), (0.0,))
run_sweep(points, SweepOptions(out=Path({str(out)!r}), mode="lockstep", jobs=4, progress_bar=False), print)
""", encoding="utf-8")
    return script


def _pids_mentioning(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and entry.name != str(os.getpid()):
            try:
                if text.encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def _recording_fake(monkeypatch) -> list[int]:
    """Stand-in point commands that write SUMMARY at once; the list of point indices they ran."""
    ran: list[int] = []

    def fake(point, mode, cfg_path, out_dir, cycles, python):
        ran.append(point.index)
        return [python, "-c", f"import pathlib; pathlib.Path({str(out_dir)!r}, 'summary.json').write_text("
                              f"{json.dumps(SUMMARY)!r})"]
    monkeypatch.setattr("sea_hil.sweep.task.point_command", fake)
    return ran


def test_killed_sweep_keeps_finished_points_and_resume_runs_only_the_rest(tmp_path, monkeypatch):
    out = tmp_path / "sw"
    proc = subprocess.Popen([sys.executable, str(_fake_sweep_script(tmp_path, out))], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        _wait_for(lambda: len(read_rows(out / "sweep.csv")) == 2, 60, "two finished points in sweep.csv")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)     # a crash: no clean-up, no final rewrite
        proc.wait()
        for pid in _pids_mentioning("sea-hil-hanging-point"):   # its point processes (own sessions) outlive it
            os.kill(pid, signal.SIGKILL)
    assert {r["point"] for r in read_rows(out / "sweep.csv")} == {"p000_tt_d0_j0_l0", "p001_et_eta0.3_r0.2_d0_j0_l0"}

    ran = _recording_fake(monkeypatch)
    points = expand_grid((0.3, 0.5, 0.8), (0.2,), (0.0,), (0.0,), (0.0,))
    lines: list[str] = []
    rows, interrupted = run_sweep(points, SweepOptions(out=out, mode="lockstep", jobs=2, resume=True, progress_bar=False),
                                  lines.append)
    assert not interrupted and sorted(ran) == [2, 3]
    assert lines[0].startswith("sweep: resuming, 2 of 4 points already in")
    assert [r["status"] for r in rows] == ["ok"] * 4
    assert [r["point"] for r in read_rows(out / "sweep.csv")] == [p.name for p in points]   # final: point order


def test_resume_recomputes_a_point_whose_config_changed(tmp_path, monkeypatch):
    ran = _recording_fake(monkeypatch)
    points = expand_grid((0.5,), (0.2,), (0.0,), (0.0,), (0.0,))
    run_sweep(points, SweepOptions(out=tmp_path, mode="lockstep", jobs=2, progress_bar=False), lambda s: None)
    changed = tmp_path / "c.toml"
    changed.write_text("[trigger]\nmax_inter_event_s = 0.2\n", encoding="utf-8")
    ran.clear()
    run_sweep(points, SweepOptions(out=tmp_path, config=changed, mode="lockstep", jobs=2, resume=True,
                                   progress_bar=False),
              lambda s: None)
    assert sorted(ran) == [0, 1]


def test_seed_axis_and_folding():
    assert seed_axis(None, 5) == (None,) and seed_axis(3, None) == (1, 2, 3) and seed_axis(2, 7) == (7, 8)
    points = expand_grid((0.5,), (0.2,), (0.0,), (0.0,), (0.0,), seed_axis(3, 1))
    assert [(p.controller, p.seed) for p in points] == [("tt", 1), ("et", 1), ("tt", 2), ("et", 2), ("tt", 3),
                                                        ("et", 3)]
    assert len({p.name for p in points}) == 6
    rows = [{"point": p.name, "controller": p.controller, "eta": p.eta or "", "r": p.r or "", "delay_ms": 0.0,
             "jitter_ms": 0.0, "loss": 0.0, "cycles": 1, "status": "ok", "downlink_msgs": 300 + 10 * p.seed,
             "max_err_rad": 0.004 + 0.001 * p.seed, "rms_err_rad": 0.001, "max_err_hip_rad": "",
             "max_err_knee_rad": ""} for p in points]
    folded = fold_seeds(rows)
    assert len(folded) == 2 and all(f["n_seeds"] == 3 for f in folded)
    et = next(f for f in folded if f["controller"] == "et")
    assert et["downlink_msgs"] == pytest.approx(320.0) and et["max_err_rad"] == pytest.approx(0.006)
    assert et["downlink_msgs_ci95"] == pytest.approx(ci95_half_width([310, 320, 330]))
    assert ci95_half_width([310, 320, 330]) == pytest.approx(4.303 * 10 / 3 ** 0.5, rel=1e-3)   # t(0.975, 2)
    assert ci95_half_width([1.0]) == 0.0
