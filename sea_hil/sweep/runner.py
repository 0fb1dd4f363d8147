"""`sea-hil sweep`: every grid point a task (`sea_hil.sweep.task.run_point`) on a Dask `distributed` cluster —
the embedded local one by default, or an existing one (`--scheduler`) — and the rows collected as they finish.

Each finished row is appended to DIR/sweep.csv at once (`sea_hil.sweep.csvlog`: a crash loses no finished point);
`resume=True` skips the points sweep.csv already holds as ok with the same effective config. A progress bar (tqdm,
on a terminal) or one plain line per point shows done / total and the rate. Ctrl-C sets a Dask `Event` that every
running point polls: they end their process groups and come back as "cancelled"; points not started are cancelled.
"""
from __future__ import annotations

import hashlib
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from distributed import Event, as_completed, wait
from tqdm import tqdm

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig
from sea_hil.config.shorthand import scenario_config
from sea_hil.sweep.cluster import open_client
from sea_hil.sweep.csvlog import CsvLog, finished, read_rows, write_csv
from sea_hil.sweep.grid import GridPoint, csv_row, point_overrides, scheme_columns
from sea_hil.sweep.task import PointSpec, run_point


@dataclass(frozen=True)
class SweepOptions:
    out: Path
    config: Path | None = None
    mode: str = "offline"             # the engine: offline (in-process session engine) or lockstep (sessions)
    cycles: int = 1
    seed: int | None = None
    jobs: int = 1
    direction: str = "both"
    scheduler: str | None = None
    resume: bool = False
    progress_bar: bool | None = None    # None: a bar on a terminal, plain lines otherwise
    disturbance: str | None = None  # --disturbance / --mismatch shorthands (sea_hil/config/shorthand.py)
    mismatch: str | None = None


def point_config(opts: SweepOptions, point: GridPoint) -> SeaHilConfig:
    """The base config (embedded defaults + --config) with the seed and the point's overrides; validated."""
    ov = point_overrides(point, opts.direction)
    seed = point.seed if point.seed is not None else opts.seed
    if seed is not None:
        ov["link"]["seed"] = seed
        ov["disturbance"] = {"seed": seed}
    return scenario_config(str(opts.config) if opts.config else None, ov, opts.disturbance, opts.mismatch)


def point_timeout_s(cfg: SeaHilConfig, cycles: int) -> float:
    """Generous wall budget for one point (run.py gives the session 60 s + 3x sim time; add start-up and output)."""
    return 120.0 + 4.0 * cfg.trajectory.period_s * cycles


def build_configs(points: list[GridPoint], opts: SweepOptions) -> dict[int, SeaHilConfig]:
    """Every point's config, validated before anything runs (a bad combination is a ConfigError up front)."""
    return {p.index: point_config(opts, p) for p in points}


def point_spec(opts: SweepOptions, point: GridPoint, cfg: SeaHilConfig, stop_event: str = "") -> PointSpec:
    toml = config_to_toml(cfg)
    return PointSpec(point, opts.mode, opts.cycles, str(opts.out), toml, hashlib.sha256(toml.encode()).hexdigest(),
                     cfg.link.seed, point_timeout_s(cfg, opts.cycles), stop_event,
                     tuple(scheme_columns(cfg).items()), cfg if opts.mode == "offline" else None)


def progress_line(done: int, total: int, elapsed_s: float, row: dict[str, Any], point: GridPoint) -> str:
    eta_s = elapsed_s / done * (total - done) if done else 0.0
    rate = done / elapsed_s if elapsed_s > 0 else 0.0
    if row["status"] == "ok":
        err = row["max_err_rad"]
        res = f"ok: {row['downlink_msgs']} downlink msgs, max err {err:.4f} rad" if err != "" else "ok"
    else:
        res = f"{row['status'].upper()}: {row['error']}"
    return (f"[{done:3d}/{total}] {elapsed_s:6.1f} s elapsed, {rate:.2f} points/s, ETA {eta_s:5.0f} s | "
            f"{point.label()} | {res} ({row['wall_s']:.1f} s)")


class _Progress:
    """tqdm bar on a terminal (done / total, rate, ETA), else one `progress_line` per finished point."""

    def __init__(self, total: int, already: int, bar: bool | None, log: Callable[[str], None]) -> None:
        self.total, self.done, self.log, self.t0 = total, already, log, time.monotonic()
        use_bar = sys.stderr.isatty() if bar is None else bar
        self._bar = None
        if use_bar:
            self._bar = tqdm(total=total, initial=already, unit="point", file=sys.stderr, dynamic_ncols=True)

    def update(self, row: dict[str, Any], point: GridPoint) -> None:
        self.done += 1
        if self._bar is not None:
            self._bar.set_postfix_str(f"{point.controller} {row['status']}", refresh=False)
            self._bar.update(1)
        else:
            self.log(progress_line(self.done, self.total, time.monotonic() - self.t0, row, point))

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _cancelled(point: GridPoint, opts: SweepOptions, cfg: SeaHilConfig) -> dict[str, Any]:
    return csv_row(point, None, cycles=opts.cycles, seed=cfg.link.seed, wall_s=0.0, status="cancelled",
                   error="sweep interrupted", scheme=scheme_columns(cfg))


def run_sweep(points: list[GridPoint], opts: SweepOptions, log: Callable[[str], None] = print,
              configs: dict[int, SeaHilConfig] | None = None) -> tuple[list[dict[str, Any]], bool]:
    """Run every point (`opts.jobs` at a time locally, or on the cluster at `opts.scheduler`); rows in point order,
    and whether the sweep was interrupted."""

    configs = configs if configs is not None else build_configs(points, opts)
    csv_path = opts.out / "sweep.csv"
    done_before = finished(read_rows(csv_path)) if opts.resume else {}
    stop_name = f"sea-hil-sweep-stop-{uuid.uuid4().hex}"
    specs = {p.index: point_spec(opts, p, configs[p.index], stop_name) for p in points}
    rows: dict[int, dict[str, Any]] = {}
    for p in points:
        old = done_before.get((p.name, specs[p.index].config_sha256))
        if old is not None:
            rows[p.index] = old
    if rows:
        log(f"sweep: resuming, {len(rows)} of {len(points)} points already in {csv_path}")
    todo = [p for p in points if p.index not in rows]
    interrupted = False
    with CsvLog(csv_path, keep_existing=opts.resume) as csv_log, open_client(opts.scheduler, opts.jobs, opts.mode) as client:
        stop = Event(stop_name, client=client)
        progress = _Progress(len(points), len(rows), opts.progress_bar, log)
        futures = {client.submit(run_point, specs[p.index], key=f"{p.name}-{specs[p.index].config_sha256[:12]}",
                                 pure=False): p for p in todo}
        try:
            direct = True if opts.scheduler is None else None   # a remote cluster's workers may be unreachable
            for batch in as_completed(futures).batches():   # one gather per batch of finished points
                for fut, row in zip(batch, client.gather(batch, direct=direct), strict=True):
                    point = futures[fut]
                    rows[point.index] = row
                    csv_log.append(row)
                    progress.update(row, point)
        except KeyboardInterrupt:
            interrupted = True
            log("sweep: interrupted, ending running points ...")
            stop.set()      # running points end their process groups and return "cancelled" rows
            pending = [f for f, p in futures.items() if p.index not in rows]
            wait(pending, timeout=60)
            for fut in pending:
                point = futures[fut]
                if fut.status == "finished":
                    rows[point.index] = fut.result()
                else:
                    fut.cancel()
                    rows[point.index] = _cancelled(point, opts, configs[point.index])
                csv_log.append(rows[point.index])
        finally:
            progress.close()
    ordered = [rows[p.index] for p in points]
    write_csv(csv_path, ordered)
    return ordered, interrupted
