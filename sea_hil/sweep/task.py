"""One sweep point as a self-contained task: what a Dask worker (local or remote) runs.

`run_point(spec)` needs only the installed package: the point's effective config travels as TOML text in the
`PointSpec`. Engine `offline` (the default): the point runs in the worker process on the offline session engine
(`sea_hil.offline.session_engine`: the lockstep session's timeline, links and quantisation, bit for bit the same
summary) and only its row comes back. Engine `lockstep`: the worker writes the config to
`<out>/points/<name>/input.toml`, runs `sea-hil run --lockstep` as its own process group and returns the CSV row. Per-point output directories are written on the
worker's file system under the same path (on one machine: next to sweep.csv). A timeout or a stop request (the
client sets the Dask `Event` named `spec.stop_event`, e.g. on Ctrl-C) ends the whole group: SIGINT first (the run
cleans up), SIGKILL after `GRACE_S`. A failing point becomes a row with its error; it never raises.
"""
from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from distributed import Event

from sea_hil.config.loader import config_from_dict
from sea_hil.errors import SeaHilError
from sea_hil.offline.gc_pause import gc_paused
from sea_hil.offline.session_engine import engine_summary
from sea_hil.sweep.grid import GridPoint, csv_row, point_command

GRACE_S = 10.0
POLL_S = 0.5


@dataclass(frozen=True)
class PointSpec:
    point: GridPoint
    mode: str
    cycles: int
    out: str                # the sweep's output directory
    config_toml: str        # the point's effective config
    config_sha256: str
    seed: int
    timeout_s: float
    stop_event: str = ""    # name of a distributed.Event that asks running points to stop ("" = none)
    scheme: tuple[tuple[str, Any], ...] = ()   # the row's effective scheme columns (grid.scheme_columns)
    config: Any = None      # engine offline: the validated config itself (config_toml's; unpickling it costs a
                            # sixth of parsing and validating the TOML again), None = parse config_toml


def _error_line(log_path: Path, returncode: int) -> str:
    try:
        lines = [ln.strip() for ln in log_path.read_text(encoding="utf-8", errors="replace").splitlines()]
    except OSError:
        lines = []
    lines = [ln for ln in lines if ln]
    errors = [ln for ln in lines if "error" in ln.lower()]
    tail = errors[-1] if errors else (lines[-1] if lines else "")
    return f"exit status {returncode}" + (f": {tail[:300]}" if tail else "")


def _signal_group(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def end_group(proc: subprocess.Popen) -> None:
    """SIGINT the point's process group, SIGKILL it after GRACE_S; also reaps leftovers of a finished point."""
    if proc.poll() is None:
        _signal_group(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=GRACE_S)
        except subprocess.TimeoutExpired:
            pass
    _signal_group(proc.pid, signal.SIGKILL)
    proc.wait()


def _stop_requested(name: str) -> Callable[[], bool]:
    if not name:
        return lambda: False
    event = Event(name)
    return event.is_set


def run_point(spec: PointSpec) -> dict[str, Any]:
    """Run one point to completion (or timeout / stop); its CSV row."""
    return (_run_offline if spec.mode == "offline" else _run_process)(spec)


def _run_offline(spec: PointSpec) -> dict[str, Any]:
    t0 = time.monotonic()
    row = functools.partial(csv_row, spec.point, cycles=spec.cycles, seed=spec.seed, config_sha256=spec.config_sha256,
                            scheme=dict(spec.scheme))
    try:
        with gc_paused():
            cfg = spec.config if spec.config is not None else config_from_dict(tomllib.loads(spec.config_toml))
            summary = engine_summary(cfg, spec.point.controller, spec.cycles)
    except SeaHilError as err:      # e.g. a diverged closed loop: the point's row says so, the sweep goes on
        return row(None, wall_s=time.monotonic() - t0, status="error", error=str(err))
    return row(summary, wall_s=time.monotonic() - t0)


def _run_process(spec: PointSpec) -> dict[str, Any]:
    t0 = time.monotonic()
    point = spec.point

    def row(summary: dict[str, Any] | None, status: str, error: str = "") -> dict[str, Any]:
        return csv_row(point, summary, cycles=spec.cycles, seed=spec.seed, wall_s=time.monotonic() - t0,
                       status=status, error=error, config_sha256=spec.config_sha256, scheme=dict(spec.scheme))

    stop = _stop_requested(spec.stop_event)
    if stop():
        return row(None, "cancelled", "sweep interrupted before this point started")
    out = Path(spec.out) / "points" / point.name
    out.mkdir(parents=True, exist_ok=True)
    cfg_path = out / "input.toml"
    cfg_path.write_text(spec.config_toml, encoding="utf-8")
    (out / "summary.json").unlink(missing_ok=True)
    cmd = point_command(point, spec.mode, cfg_path, out, spec.cycles, python=sys.executable)
    log_path = out / "run.log"
    with log_path.open("w", encoding="utf-8") as log_fh:
        log_fh.write(" ".join(cmd) + "\n")
        log_fh.flush()
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log_fh, stderr=subprocess.STDOUT,
                                start_new_session=True)
        deadline = time.monotonic() + spec.timeout_s
        stopped = False
        try:
            while proc.poll() is None:
                if stop():
                    stopped = True
                    break
                if time.monotonic() > deadline:
                    return row(None, "timeout", f"no result within {spec.timeout_s:.0f} s")
                try:
                    proc.wait(timeout=POLL_S)
                except subprocess.TimeoutExpired:
                    pass
        finally:
            end_group(proc)
    rc = proc.returncode
    if stopped or (rc != 0 and stop()):
        return row(None, "cancelled", "sweep interrupted")
    if rc != 0:
        return row(None, "error", _error_line(log_path, rc))
    try:
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        return row(None, "error", f"no readable summary.json: {err}")
    return row(summary, "ok")
