"""bench/bench_soak.py's pure parts: RSS growth after the first minute from sampled series, and its records."""
from __future__ import annotations

import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench"
sys.path.insert(0, str(BENCH))

import bench_soak  # noqa: E402


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
    rss, can, zen, comp = bench_soak.soak_records(g, rec, 5.0, "ok", 300.0, "python bench/bench_soak.py")
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
