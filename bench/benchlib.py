"""Shared helpers of the bench/ scripts: result records (JSON), host facts, statistics, a CPU loader and
`sea-hil run` invocations.

A result record is one row of BENCHMARKS.md:
{figure, title, command, runs, metric, unit, median, p99, min, max, baseline, baseline_label, ratio, goal, goal_met,
 date, host, notes, details}. `median`/`min`/`max` are over the per-run values of `metric`; `p99` is said per figure
(pooled samples or the median of per-run p99s, see `metric`). `details` is a list of flat dicts (extra table).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import selectors
import shlex
import socket
import subprocess
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from sea_hil.errors import SeaHilError
from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parent.parent


def bench_args(description: str, runs: int) -> argparse.ArgumentParser:
    """An argument parser with the common `--runs`, `--json` and `--quick` options."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--runs", type=int, default=runs, help=f"number of runs (default {runs})")
    ap.add_argument("--json", type=Path, metavar="OUT", help="write the result record(s) to this JSON file")
    ap.add_argument("--quick", action="store_true", help="smoke mode: tiny sizes, numbers not meaningful")
    return ap


def command_line(argv: Sequence[str] | None = None) -> str:
    """The command that reproduces this run (`python -m bench.NAME ARGS`, without --json); the script's path when
    it was not run as a module."""
    args = list(sys.argv[1:] if argv is None else argv)
    if "--json" in args:
        i = args.index("--json")
        del args[i:i + 2]
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    if spec is not None and spec.name.startswith("bench."):
        return shlex.join(["python", "-m", spec.name, *args])
    script = Path(sys.argv[0]).resolve()
    try:
        script_s = str(script.relative_to(REPO))
    except ValueError:
        script_s = str(script)
    return shlex.join(["python", script_s, *args])


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "?"


def host_facts() -> dict[str, Any]:
    """Facts that qualify a measurement: host, CPU, cores, load average, kernel, Python and key library versions."""
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    return {"hostname": socket.gethostname(), "cpu": _cpu_model(), "cores": os.cpu_count(),
            "loadavg_1m": round(load[0], 2), "kernel": platform.release(), "python": platform.python_version(),
            "eclipse-zenoh": _version("eclipse-zenoh"), "python-can": _version("python-can"),
            "mcap": _version("mcap")}


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def pct(values: Sequence[float] | np.ndarray, q: float) -> float:
    """Percentile `q` (0-100) with the `inverted_cdf` rule (an observed value); NaN for no values."""
    arr = np.asarray(values, dtype=float)
    return float(np.percentile(arr, q, method="inverted_cdf")) if arr.size else math.nan


def record(figure: str, title: str, *, runs: int, metric: str, unit: str, per_run: Sequence[float], p99: float,
           baseline: float | None = None, baseline_label: str = "", goal: str = "", goal_met: bool | None = None,
           notes: str = "", details: list[dict[str, Any]] | None = None, command: str | None = None,
           median: float | None = None, p99_unit: str | None = None) -> dict[str, Any]:
    """A result record; `per_run` gives min/max and (unless `median` is given) the median; `ratio` = median /
    baseline when there is a baseline. `p99_unit`: the p99 column's unit where the figure's p99 is another
    quantity than its metric (default: `unit`)."""
    vals = [float(v) for v in per_run]
    med = median if median is not None else (float(np.median(vals)) if vals else math.nan)
    ratio = med / baseline if baseline not in (None, 0) and math.isfinite(med) else None
    return {"figure": figure, "title": title, "command": command or command_line(), "runs": runs, "metric": metric,
            "unit": unit, "median": med, "p99": float(p99), "min": min(vals, default=math.nan),
            "max": max(vals, default=math.nan), "per_run": vals, "baseline": baseline,
            "baseline_label": baseline_label, "ratio": ratio, "goal": goal, "goal_met": goal_met, "date": now_iso(),
            "host": host_facts(), "notes": notes, "details": details or [],
            **({"p99_unit": p99_unit} if p99_unit is not None else {})}


def _clean(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        return _clean(obj.item())
    return obj


def emit(records: list[dict[str, Any]], out: Path | None) -> None:
    """Print a short summary of each record and write them (a JSON list) to `out` if given."""
    for r in records:
        base = f"  baseline {r['baseline']:.4g}" if r.get("baseline") is not None else ""
        print(f"[fig {r['figure']}] {r['title']}: median {r['median']:.4g} {r['unit']}  p99 {r['p99']:.4g}  "
              f"min {r['min']:.4g}  max {r['max']:.4g}{base}  goal_met={r['goal_met']}", flush=True)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(_clean(records), indent=2) + "\n", encoding="utf-8")


@contextmanager
def cpu_loader(enabled: bool = True) -> Iterator[subprocess.Popen[bytes] | None]:
    """A busy-loop subprocess keeping one core busy while the block runs; killed and reaped afterwards."""
    if not enabled:
        yield None
        return
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield hog
    finally:
        hog.kill()
        hog.wait(timeout=10.0)


def wait_ready(proc: subprocess.Popen[bytes], timeout_s: float = 20.0) -> None:
    """Wait until child `proc` prints the line `ready` on its stdout pipe (SeaHilError after `timeout_s`)."""
    sel = selectors.DefaultSelector()
    assert proc.stdout is not None
    sel.register(proc.stdout, selectors.EVENT_READ)
    if not sel.select(timeout_s) or proc.stdout.readline().strip() != b"ready":
        raise SeaHilError(f"child process {proc.args!r} did not become ready")


def stop_process(proc: subprocess.Popen[bytes]) -> None:
    """Terminate a child, kill it if it does not end within 5 s, and reap it."""
    end_process(proc)


def sea_hil_run(out: Path, *, controller: str = "et", lockstep: bool = False, cycles: int = 1,
                extra: Sequence[str] = (), timeout_s: float = 300.0) -> dict[str, Any]:
    """Run `sea-hil run` in a child process (the real CLI) and return its summary.json; a failed run raises
    SeaHilError with the tail of its output."""
    cmd = [sys.executable, "-m", "sea_hil.cli", "run", "--controller", controller, "--cycles", str(cycles),
           "--out", str(out), "--quiet", *(["--lockstep"] if lockstep else []), *extra]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        output, _ = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode != 0:
        raise SeaHilError(f"{shlex.join(cmd)} failed ({proc.returncode}):\n{output.decode(errors='replace')[-2000:]}")
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


def sea_hil_run_cmd(controller: str, lockstep: bool, cycles: int = 1) -> str:
    return (f"sea-hil run --controller {controller} --cycles {cycles}"
            f"{' --lockstep' if lockstep else ''} --out DIR")
