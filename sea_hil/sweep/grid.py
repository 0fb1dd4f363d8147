"""The `sea-hil sweep` grid, pure: parsing the axes, expanding the points, per-point config overrides and commands,
CSV rows from summary.json dicts, and the Pareto front. No I/O here (see sea_hil/sweep/runner.py)."""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from sea_hil.errors import ConfigError

# axis name -> (lower bound, lower bound allowed?, upper bound or None)
AXES: dict[str, tuple[float, bool, float | None]] = {
    "eta": (0.0, False, None), "r": (0.0, False, None), "delay-ms": (0.0, True, None),
    "jitter-ms": (0.0, True, None), "loss": (0.0, True, 1.0)}
DIRECTIONS = ("both", "uplink", "downlink")
CSV_COLUMNS = ("point", "controller", "eta", "r", "delay_ms", "jitter_ms", "loss", "cycles", "seed",
               "downlink_msgs", "downlink_bytes", "uplink_msgs", "max_err_hip_rad", "max_err_knee_rad", "max_err_rad",
               "rms_err_hip_rad", "rms_err_knee_rad", "rms_err_rad", "latency_p50_us", "latency_p99_us", "wall_s", "status", "error",
               "config_sha256")


def parse_axis(name: str, text: str) -> tuple[float, ...]:
    """'0.3,0.5' -> (0.3, 0.5); a ConfigError naming the option for empty, non-numeric, non-finite, out-of-range or
    repeated values."""
    lo, lo_ok, hi = AXES[name]
    parts = [p.strip() for p in text.split(",")]
    if not text.strip() or any(not p for p in parts):
        raise ConfigError(f"--{name} {text!r}: expected comma-separated numbers, e.g. 0.3,0.5")
    values = []
    for p in parts:
        try:
            v = float(p)
        except ValueError as err:
            raise ConfigError(f"--{name}: {p!r} is not a number") from err
        if not math.isfinite(v):
            raise ConfigError(f"--{name}: {p!r} is not finite")
        if v < lo or (v == lo and not lo_ok) or (hi is not None and v > hi):
            bound = f"{'>=' if lo_ok else '>'} {lo:g}" + (f" and <= {hi:g}" if hi is not None else "")
            raise ConfigError(f"--{name}: {p} out of range (must be {bound})")
        values.append(v)
    if len(set(values)) != len(values):
        raise ConfigError(f"--{name} {text!r}: repeated value")
    return tuple(values)


@dataclass(frozen=True)
class LinkCondition:
    delay_ms: float
    jitter_ms: float
    loss: float

    def label(self) -> str:
        return f"delay {self.delay_ms:g} ms, jitter {self.jitter_ms:g} ms, loss {self.loss:g}"


@dataclass(frozen=True)
class GridPoint:
    """One session of the sweep. TT reference points have eta = r = None (the trigger is not used); `seed` None =
    the sweep's --seed (or the config's) for every point, else this point's seed (the seeds axis)."""
    index: int
    controller: str
    link: LinkCondition
    eta: float | None = None
    r: float | None = None
    seed: int | None = None

    @property
    def name(self) -> str:
        trig = f"_eta{self.eta:g}_r{self.r:g}" if self.controller == "et" else ""
        lk = self.link
        seed = "" if self.seed is None else f"_s{self.seed}"
        return f"p{self.index:03d}_{self.controller}{trig}_d{lk.delay_ms:g}_j{lk.jitter_ms:g}_l{lk.loss:g}{seed}"

    def label(self) -> str:
        trig = f" eta={self.eta:g} r={self.r:g}" if self.controller == "et" else ""
        seed = "" if self.seed is None else f" | seed {self.seed}"
        return f"{self.controller}{trig} | {self.link.label()}{seed}"


def expand_grid(eta: Sequence[float], r: Sequence[float], delay_ms: Sequence[float], jitter_ms: Sequence[float],
                loss: Sequence[float], seeds: Sequence[int | None] = (None,)) -> list[GridPoint]:
    """Per link condition (delay x jitter x loss) and seed: one TT reference, then every ET (eta x r) point."""
    points: list[GridPoint] = []
    for d, j, l in itertools.product(delay_ms, jitter_ms, loss):
        link = LinkCondition(d, j, l)
        for seed in seeds:
            points.append(GridPoint(len(points), "tt", link, seed=seed))
            for e, rr in itertools.product(eta, r):
                points.append(GridPoint(len(points), "et", link, e, rr, seed))
    return points


def seed_axis(n_seeds: int | None, base_seed: int | None) -> tuple[int | None, ...]:
    """`--seeds N`: the seeds base, base + 1, ..., base + N - 1 (base = --seed, default 1); no axis: (None,)."""
    if n_seeds is None:
        return (None,)
    if n_seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, not {n_seeds}")
    base = 1 if base_seed is None else base_seed
    return tuple(range(base, base + n_seeds))


def point_overrides(point: GridPoint, direction: str = "both") -> dict[str, Any]:
    """Nested config overrides (for sea_hil.config.load_config) that put this point's trigger and link in place."""
    if direction not in DIRECTIONS:
        raise ConfigError(f"link direction must be one of {', '.join(DIRECTIONS)}, not {direction!r}")
    lk = point.link
    one = {"delay_s": lk.delay_ms / 1000.0, "jitter_s": lk.jitter_ms / 1000.0, "loss": lk.loss}
    dirs = ("uplink", "downlink") if direction == "both" else (direction,)
    ov: dict[str, Any] = {"link": {d: dict(one) for d in dirs}}
    if point.controller == "et":
        ov["trigger"] = {"eta": point.eta, "r": point.r}
    return ov


def point_command(point: GridPoint, mode: str, cfg_path: Path, out: Path, cycles: int,
                  python: str = "python3") -> list[str]:
    """The `sea-hil run --lockstep` command line of one point (engine lockstep)."""
    if mode != "lockstep":
        raise ConfigError(f"only the lockstep engine runs a point as a process, not {mode!r}")
    return [python, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet"] + ["--controller", point.controller, "--config", str(cfg_path), "--cycles", str(cycles),
                  "--out", str(out)]


def _tx(summary: dict[str, Any]) -> tuple[Any, Any, Any]:
    t = summary.get("transmissions") or {}
    return t.get("downlink_msgs", ""), t.get("downlink_bytes", ""), t.get("uplink_msgs", "")


def csv_row(point: GridPoint, summary: dict[str, Any] | None, *, cycles: int, seed: int, wall_s: float,
            status: str = "ok", error: str = "", config_sha256: str = "") -> dict[str, Any]:
    """One CSV row (keys = CSV_COLUMNS); `summary` is the point's summary.json (None if the point failed)."""
    row: dict[str, Any] = {c: "" for c in CSV_COLUMNS}
    row.update(point=point.name, controller=point.controller, eta="" if point.eta is None else point.eta,
               r="" if point.r is None else point.r, delay_ms=point.link.delay_ms, jitter_ms=point.link.jitter_ms,
               loss=point.link.loss, cycles=cycles, seed=seed, wall_s=round(wall_s, 3), status=status,
               error=" ".join(error.split()), config_sha256=config_sha256)
    if summary is None:
        return row
    row["downlink_msgs"], row["downlink_bytes"], row["uplink_msgs"] = _tx(summary)
    tracking = summary.get("tracking", {})
    mx, rms = tracking.get("max_abs_error_rad"), tracking.get("rms_error_rad")
    if mx:
        row.update(max_err_hip_rad=mx[0], max_err_knee_rad=mx[1], max_err_rad=max(mx))
    if rms:
        row.update(rms_err_hip_rad=rms[0], rms_err_knee_rad=rms[1], rms_err_rad=max(rms))
    timing = summary.get("timing") or {}
    lat = timing.get("latency_us")
    if isinstance(lat, dict) and timing.get("latency_samples", 0) > 0:
        row.update(latency_p50_us=lat.get("p50", ""), latency_p99_us=lat.get("p99", ""))
    return row


def pareto_front(xy: Sequence[tuple[float, float]]) -> list[bool]:
    """For each (x, y), True if no other point is <= in both and < in one (both minimised). Equal points are all
    on the front."""
    def dominated(i: int) -> bool:
        xi, yi = xy[i]
        return any(xj <= xi and yj <= yi and (xj < xi or yj < yi) for j, (xj, yj) in enumerate(xy) if j != i)
    return [not dominated(i) for i in range(len(xy))]
