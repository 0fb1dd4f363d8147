"""TT is periodic at every trigger placement (issue 29, part 4): with the trigger at the edge (the default scheme) the
time-triggered baseline publishes a state every outer period however many answers are in flight. Before the fix the
edge's "answer in flight" gate made it stop-and-wait: lockstep seed 0, 5 ms +- 1 ms / 1 % each way, 488 states of
1001; 20 ms / 5 ms jitter / Gilbert-Elliott each way, 298 states and the limb lost (0.37 / 0.77 rad).

Four live 10 s lockstep sessions, seed 1 (`JOBS` at a time): TT with `--trigger edge` and with `--trigger controller`
on both links. The edge sends 1001 +- 2 states in the measured cycle (`events_by_reason`: the edge's tracking records
of the states it published) and tracks within 1.2x of TT with the trigger at the controller on the same link (max
and RMS error per joint)."""
from __future__ import annotations

import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[1]
LINKS = {"5ms_loss": "delay=5ms,jitter=1ms,loss=1%", "20ms_ge": "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"}
JOBS = 2


def _run(out: Path, placement: str, spec: str) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--controller", "tt",
                           "--cycles", "1", "--seed", "1", "--no-figures", "--trigger", placement,
                           "--uplink", spec, "--downlink", spec, "--out", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


def test_tt_with_the_trigger_at_the_edge_is_periodic_and_tracks_as_tt_at_the_controller(tmp_path: Path) -> None:
    runs = [(link, placement) for link in LINKS for placement in ("edge", "controller")]
    with ThreadPoolExecutor(JOBS) as pool:
        futures = {run: pool.submit(_run, tmp_path / f"{run[0]}_{run[1]}", run[1], LINKS[run[0]]) for run in runs}
        summaries = {run: f.result() for run, f in futures.items()}
    for link in LINKS:
        edge, ctl = summaries[(link, "edge")], summaries[(link, "controller")]
        assert set(edge["events_by_reason"]) == {"TIME"}
        assert abs(edge["events_by_reason"]["TIME"] - 1001) <= 2, (link, edge["events_by_reason"])
        assert edge["edge"]["edge_retriggers"] == 0               # nothing held back, so nothing re-triggered
        for key in ("max_abs_error_rad", "rms_error_rad"):
            for joint in (0, 1):
                e, c = edge["tracking"][key][joint], ctl["tracking"][key][joint]
                assert e <= 1.2 * c, (link, key, joint, e, c)
