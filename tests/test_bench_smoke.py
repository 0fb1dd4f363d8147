"""Smoke tests of bench/: each script in its quickest mode writes well-formed result records (shape, not timing),
and run_all's parsers and markdown renderer work. The scripts needing a full `sea-hil run` session (figures 3 and
5, and run_all itself) are covered through their pure record builders."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench import bench_bandwidth, bench_closed_loop_latency, run_all
from bench.report_md import render
from sea_hil.runtime import timer_floor

REPO = Path(__file__).resolve().parent.parent

KEYS = {"figure", "title", "command", "runs", "metric", "unit", "median", "p99", "min", "max", "baseline", "goal",
        "goal_met", "date", "host", "notes", "details"}


def _run_script(name: str, tmp_path: Path, *args: str) -> list[dict]:
    out = tmp_path / f"{name}.json"
    proc = subprocess.run([sys.executable, "-m", f"bench.{name}", *args, "--json", str(out)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    records = json.loads(out.read_text())
    _check_shape(records)
    return records


def _check_shape(records: list[dict]) -> None:
    assert isinstance(records, list) and records
    for r in records:
        assert KEYS <= set(r), KEYS - set(r)
        assert r["command"].startswith("python -m bench.")
        assert "--json" not in r["command"]
        assert r["runs"] >= 1 and r["host"]["cores"] >= 1
        assert r["goal_met"] in (True, False, None)


@pytest.mark.slow
def test_zenoh_hop_quick(tmp_path):
    (rec,) = _run_script("bench_zenoh_hop", tmp_path, "--quick")
    assert rec["figure"] == "2" and rec["baseline"] > 0 and rec["median"] > 0
    assert {d["mode"] for d in rec["details"]} == {"raw", "project", "blocking"}
    assert all(d["hops"] + d["lost"] == 50 for d in rec["details"])


@pytest.mark.slow
def test_driver_timing_quick_with_edge(tmp_path):
    recs = _run_script("bench_driver_timing", tmp_path, "--quick", "--edge")
    assert [r["figure"] for r in recs] == ["4a", "4c"]
    (row,) = recs[0]["details"]
    assert row["ticks"] > 0 and row["edge_samples"] > 0 and row["edge_commands"] > 0


def test_ipc_bus_quick(tmp_path):
    recs = _run_script("bench_ipc_bus", tmp_path, "--quick", "--runs", "1")
    assert [r["figure"] for r in recs] == ["ipc-t", "ipc-l", "ipc-s"]
    assert all(d["lost"] == 0 and d["disordered"] == 0 and d["received"] == 2000 for d in recs[0]["details"])
    assert recs[0]["goal_met"] and recs[2]["goal_met"] and recs[1]["median"] > 0


def test_timer_floor_quick(tmp_path):
    (rec,) = _run_script("bench_timer_floor", tmp_path, "--quick")
    assert rec["figure"] == "4f" and rec["details"][0]["deadlines"] == 1000 and rec["p99"] >= 0
    # its p99 is a lateness in us, the metric a percentage: the table's p99 column says so
    row = next(ln for ln in render([rec], preliminary=True, total_s=1.0, header="h").splitlines()
               if ln.startswith("| 4f |"))
    assert row.split(" | ")[5].endswith(" us") and row.split(" | ")[4].endswith(" %"), row


def test_timer_floor_counts_a_late_wake_up_as_the_deadlines_it_passed(monkeypatch):
    """On a fake clock: every sleep wakes 10 us late, the 3rd 2.5 periods late -> 2 deadlines lost, the next tick
    due at the 6th deadline (no bunching), and the run still ends at its last deadline."""
    now = [0]
    sleeps = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        now[0] += round(s * 1e9) + (2_500_000 if len(sleeps) == 3 else 10_000)
    monkeypatch.setattr(timer_floor.time, "monotonic_ns", lambda: now[0])
    monkeypatch.setattr(timer_floor.time, "sleep", sleep)
    row = timer_floor.empty_loop(0.010)   # the product's loop, which bench_timer_floor and `sea-hil run` measure
    assert (row["deadlines"], row["misses"], row["ticks"]) == (10, 2, 8)
    assert row["miss_pct"] == 20.0 and row["lateness_us_max"] == 2500.0 and row["lateness_us_p50"] == 10.0


@pytest.mark.slow
def test_scale_quick(tmp_path):
    (rec,) = _run_script("bench_scale", tmp_path, "--quick")
    assert [d["limbs"] for d in rec["details"]][:1] == [1]
    assert rec["per_run"][0] in (0, 1, 2)
    assert "% of a bus" in rec["notes"]


@pytest.mark.slow
def test_mcap_quick_on_a_small_session(tmp_path):
    from sea_hil.recorder.writer import SessionRecorder
    src = tmp_path / "small.mcap"
    with SessionRecorder(src) as rec:
        for i in range(300):
            t = 1_000_000 * i
            rec.record("/can/raw", t, t, {"can_id": 33, "dlc": 8, "data_hex": f"{i:016x}", "direction": "rx"})
            rec.record("/can/feedback", t, t, {"node_id": 1, "seq": i % 256, "theta1_rad": 0.001 * i})
    recs = _run_script("bench_mcap", tmp_path, "--quick", "--session", str(src))
    assert [r["figure"] for r in recs] == ["7", "7b"]
    assert recs[0]["details"][0]["written"] == 600 and recs[0]["details"][0]["dropped"] == 0


def _summary(controller: str, downlink: int) -> dict:
    return {"controller": controller, "transmissions": {"downlink_msgs": downlink, "downlink_bytes": 53 * downlink,
                                                        "uplink_msgs": 1000},
            "tracking": {"max_abs_error_rad": [0.01, 0.02], "rms_error_rad": [0.001, 0.002]},
            "duration_s": 10.0, "timing": {"wall_s": 11.0, "latency_us": {"min": 500.0, "p50": 900.0, "p90": 1500.0,
                                                                         "p99": 2500.0, "max": 4000.0}}}


def test_bandwidth_and_latency_records():
    rows = [bench_bandwidth._row(_summary("et", 300), "realtime", 1),
            bench_bandwidth._row(_summary("tt", 1000), "realtime", 1)]
    rec = bench_bandwidth._record("realtime", "5a", rows, 1, "python -m bench.bench_bandwidth")
    _check_shape([rec])
    assert rec["median"] == 300 and rec["baseline"] == 1000 and rec["ratio"] == pytest.approx(0.3)
    assert rec["goal_met"] is True
    def lat(p99_us: float, p50_us: float = 400.0) -> dict:     # issue 33's goal: p50 <= 500 us, p99 <= 1500 us
        return bench_closed_loop_latency.latency_record(
            [{"p50_us": p50_us, "p99_us": p99_us}, {"p50_us": p50_us + 200.0, "p99_us": p99_us}], "et",
            "python -m bench.l")
    ok, bad, slow = lat(1500.0), lat(1600.0), lat(1000.0, 401.0)
    _check_shape([ok, bad, slow])
    assert (ok["median"], ok["min"], ok["max"], ok["p99"]) == (500.0, 400.0, 600.0, 1500.0)
    assert ok["goal_met"] is True and bad["goal_met"] is False and slow["goal_met"] is False


def test_run_all_parsers_and_render():
    sim = run_all.parse_simulate("CPU s per run: median 0.300  min 0.250  max 0.400\n", "python -m bench.x", 3)
    lock = run_all.parse_lockstep('{"runs": 3, "cycles": 1, "et": {"session_wall_s_per_cycle": {"median": 9.0, '
                                  '"min": 8.5, "max": 9.5}, "process_wall_s_per_cycle": {"median": 11.0}}}',
                                  "python -m bench.y", 3)
    _check_shape(sim + lock)
    assert (sim[0]["median"], sim[0]["min"], sim[0]["max"]) == (0.3, 0.25, 0.4)
    assert lock[0]["figure"] == "1b" and lock[0]["median"] == 9.0
    failed = {"figure": "2", "title": "bench_zenoh_hop", "command": "python -m bench.bench_zenoh_hop",
              "error": "boom", "date": "now"}
    md = render(sim + lock + [failed], preliminary=True, total_s=1.0, header="hdr")
    assert "PRELIMINARY" in md and "FAILED: boom" in md
    assert md.count("\n| 1") == 2   # one table row per record of figure 1
    with pytest.raises(ValueError):
        run_all.parse_simulate("nothing useful", "cmd", 1)


def test_a_file_of_figures_from_two_machines_names_each_figures_machine():
    """After `run_all.py --only`, BENCHMARKS.md holds figures of earlier runs, maybe of another host: the header lists
    both (newest first) and each figure's notes say where it was measured; one machine: no per-figure host."""
    amd = {"hostname": "vm", "cpu": "AMD EPYC", "cores": 2, "kernel": "k1", "loadavg_1m": 1.0}
    intel = {**amd, "cpu": "Intel(R) Xeon(R) Processor", "kernel": "k2"}
    base = {"title": "t", "command": "c", "runs": 1, "metric": "m", "unit": "us", "median": 1.0, "p99": 1.0,
            "min": 1.0, "max": 1.0, "goal": "", "goal_met": None}
    old = {**base, "figure": "1", "date": "2026-12-01T18:00:00Z", "host": amd}
    new = {**base, "figure": "2", "date": "2026-12-02T02:00:00Z", "host": intel}
    md = render([old, new], preliminary=False, total_s=1.0, header="hdr")
    assert "Hosts: vm (Intel(R) Xeon(R) Processor, 2 cores, kernel k2); vm (AMD EPYC, 2 cores, kernel k1)" in md
    assert "Measured 2026-12-01T18:00:00Z on vm (AMD EPYC" in md and "Measured 2026-12-02T02:00:00Z on vm (Intel" in md
    one = render([old], preliminary=False, total_s=1.0, header="hdr")
    assert "Host: vm (AMD EPYC" in one and " on vm (" not in one


def test_secure_latency_record_pairs_each_secure_run_with_its_plain_one():
    plain = [{"run": 1, "p50_us": 1000.0, "p99_us": 3000.0}, {"run": 2, "p50_us": 2000.0, "p99_us": 4000.0}]
    secure = [{"run": 1, "p50_us": 1200.0, "p99_us": 3300.0}, {"run": 2, "p50_us": 2100.0, "p99_us": 6000.0}]
    base = bench_closed_loop_latency.latency_record(plain, "et", "python -m bench.l")
    rec = bench_closed_loop_latency.secure_record(secure, plain, base, "python -m bench.l --secure")
    _check_shape([rec])
    assert [d["pair_p50_ratio"] for d in rec["details"]] == pytest.approx([1.2, 1.05])
    assert [d["pair_p99_ratio"] for d in rec["details"]] == pytest.approx([1.1, 1.5])
    assert rec["baseline"] == 1500.0 and rec["ratio"] == pytest.approx(1650.0 / 1500.0)
    assert "p50 x1.12, p99 x1.30" in rec["notes"]
