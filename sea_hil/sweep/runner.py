"""`sea-hil sweep`: run every grid point as its own `sea-hil run --lockstep` (or offline `simulate`) process, `jobs`
at a time, and collect the rows.

Each point gets DIR/points/<name>/ with its effective `input.toml` (base config + the point's trigger and link
overrides), the session output and `run.log`. A point process runs in its own process group (its controller child
included), so a timeout or Ctrl-C ends the whole group: SIGINT first (the run cleans up), SIGKILL after a grace
period. A failing point becomes a row with its error; it does not stop the sweep.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from sea_hil.config import SeaHilConfig, config_to_toml
from sea_hil.config.shorthand import scenario_config
from sea_hil.sweep.grid import GridPoint, csv_row, point_command, point_overrides

GRACE_S = 10.0


@dataclass(frozen=True)
class SweepOptions:
    out: Path
    config: Path | None = None
    mode: str = "lockstep"
    cycles: int = 1
    seed: int | None = None
    jobs: int = 1
    direction: str = "both"
    disturbance: str | None = None  # --disturbance / --mismatch shorthands (sea_hil/config/shorthand.py)
    mismatch: str | None = None


def point_config(opts: SweepOptions, point: GridPoint) -> SeaHilConfig:
    """The base config (embedded defaults + --config) with the seed and the point's overrides; validated."""
    ov = point_overrides(point, opts.direction)
    if opts.seed is not None:
        ov["link"]["seed"] = opts.seed
        ov["disturbance"] = {"seed": opts.seed}
    return scenario_config(str(opts.config) if opts.config else None, ov, opts.disturbance, opts.mismatch)


def point_timeout_s(cfg: SeaHilConfig, cycles: int) -> float:
    """Generous wall budget for one point (run.py gives the session 60 s + 3x sim time; add start-up and output)."""
    return 120.0 + 4.0 * cfg.trajectory.period_s * cycles


def _error_line(log_path: Path, returncode: int) -> str:
    try:
        lines = [ln.strip() for ln in log_path.read_text(encoding="utf-8", errors="replace").splitlines()]
    except OSError:
        lines = []
    lines = [ln for ln in lines if ln]
    errors = [ln for ln in lines if "error" in ln.lower()]
    tail = errors[-1] if errors else (lines[-1] if lines else "")
    return f"exit status {returncode}" + (f": {tail[:300]}" if tail else "")


class SweepRunner:
    """Runs points as process groups; thread-safe; `stop()` ends every running group and cancels the rest."""

    def __init__(self, opts: SweepOptions, configs: dict[int, SeaHilConfig]) -> None:
        self.opts, self.configs = opts, configs
        self._lock = threading.Lock()
        self._procs: dict[int, subprocess.Popen] = {}
        self._stopping = threading.Event()

    def run_point(self, point: GridPoint) -> dict[str, Any]:
        cfg = self.configs[point.index]
        t0 = time.monotonic()

        def row(summary: dict[str, Any] | None, status: str, error: str = "") -> dict[str, Any]:
            return csv_row(point, summary, cycles=self.opts.cycles, seed=cfg.link.seed,
                           wall_s=time.monotonic() - t0, status=status, error=error)

        if self._stopping.is_set():
            return row(None, "cancelled", "sweep interrupted before this point started")
        out = self.opts.out / "points" / point.name
        out.mkdir(parents=True, exist_ok=True)
        cfg_path = out / "input.toml"
        cfg_path.write_text(config_to_toml(cfg), encoding="utf-8")
        (out / "summary.json").unlink(missing_ok=True)
        cmd = point_command(point, self.opts.mode, cfg_path, out, self.opts.cycles, python=sys.executable)
        log_path = out / "run.log"
        with log_path.open("w", encoding="utf-8") as log_fh:
            log_fh.write(" ".join(cmd) + "\n")
            log_fh.flush()
            with self._lock:
                if self._stopping.is_set():
                    return row(None, "cancelled", "sweep interrupted before this point started")
                proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log_fh, stderr=subprocess.STDOUT,
                                        start_new_session=True)
                self._procs[point.index] = proc
            try:
                rc = proc.wait(timeout=point_timeout_s(cfg, self.opts.cycles))
            except subprocess.TimeoutExpired:
                return row(None, "timeout", f"no result within {point_timeout_s(cfg, self.opts.cycles):.0f} s")
            finally:
                self._end_group(proc)
                with self._lock:
                    self._procs.pop(point.index, None)
        if self._stopping.is_set() and rc != 0:
            return row(None, "cancelled", "sweep interrupted")
        if rc != 0:
            return row(None, "error", _error_line(log_path, rc))
        try:
            summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            return row(None, "error", f"no readable summary.json: {err}")
        return row(summary, "ok")

    @staticmethod
    def _end_group(proc: subprocess.Popen) -> None:
        """SIGINT the point's process group, SIGKILL it after GRACE_S; also reaps leftovers of a finished point."""
        pgid = proc.pid
        if proc.poll() is None:
            _signal_group(pgid, signal.SIGINT)
            try:
                proc.wait(timeout=GRACE_S)
            except subprocess.TimeoutExpired:
                pass
        _signal_group(pgid, signal.SIGKILL)
        proc.wait()

    def stop(self) -> None:
        """Cancel points not yet started and interrupt running ones (their threads then reap them)."""
        with self._lock:
            self._stopping.set()
            procs = list(self._procs.values())
        for proc in procs:
            if proc.poll() is None:
                _signal_group(proc.pid, signal.SIGINT)


def _signal_group(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def progress_line(done: int, total: int, elapsed_s: float, row: dict[str, Any], point: GridPoint) -> str:
    eta_s = elapsed_s / done * (total - done) if done else 0.0
    if row["status"] == "ok":
        err = row["max_err_rad"]
        res = f"ok: {row['downlink_msgs']} downlink msgs, max err {err:.4f} rad" if err != "" else "ok"
    else:
        res = f"{row['status'].upper()}: {row['error']}"
    return (f"[{done:3d}/{total}] {elapsed_s:6.1f} s elapsed, ETA {eta_s:5.0f} s | {point.label()} | {res} "
            f"({row['wall_s']:.1f} s)")


def build_configs(points: list[GridPoint], opts: SweepOptions) -> dict[int, SeaHilConfig]:
    """Every point's config, validated before anything runs (a bad combination is a ConfigError up front)."""
    return {p.index: point_config(opts, p) for p in points}


def run_sweep(points: list[GridPoint], opts: SweepOptions, log: Callable[[str], None] = print,
              configs: dict[int, SeaHilConfig] | None = None) -> tuple[list[dict[str, Any]], bool]:
    """Run every point (`opts.jobs` in parallel); rows in point order, and whether the sweep was interrupted."""
    configs = configs if configs is not None else build_configs(points, opts)
    runner = SweepRunner(opts, configs)
    rows: dict[int, dict[str, Any]] = {}
    t0 = time.monotonic()
    interrupted = False
    pool = ThreadPoolExecutor(max_workers=max(1, opts.jobs), thread_name_prefix="sweep")
    futures: dict[Future, GridPoint] = {pool.submit(runner.run_point, p): p for p in points}
    try:
        for fut in as_completed(futures):
            point = futures[fut]
            rows[point.index] = fut.result()
            log(progress_line(len(rows), len(points), time.monotonic() - t0, rows[point.index], point))
    except KeyboardInterrupt:
        interrupted = True
        log("sweep: interrupted, ending running points ...")
        runner.stop()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    for fut, point in futures.items():
        if point.index not in rows:
            rows[point.index] = (fut.result() if fut.done() and not fut.cancelled() else
                                 csv_row(point, None, cycles=opts.cycles, seed=configs[point.index].link.seed,
                                         wall_s=0.0, status="cancelled", error="sweep interrupted"))
    return [rows[p.index] for p in points], interrupted
