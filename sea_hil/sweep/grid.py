"""The `sea-hil sweep` grid, pure: parsing the axes, expanding the points, per-point config overrides and commands,
CSV rows from summary.json dicts, and the Pareto front. No I/O here (see sea_hil/sweep/runner.py)."""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sea_hil.errors import ConfigError
from sea_hil.protocol.link import parse_link_spec
from sea_hil.sweep.methods import Scheme

# axis name -> (lower bound, lower bound allowed?, upper bound or None)
AXES: dict[str, tuple[float, bool, float | None]] = {
    "eta": (0.0, False, None), "r": (0.0, False, None), "delay-ms": (0.0, True, None),
    "jitter-ms": (0.0, True, None), "loss": (0.0, True, 1.0),
    "period-ms": (-math.inf, True, None)}   # sign and multiple: commands/common.py check_period_ms
DIRECTIONS = ("both", "uplink", "downlink")
SCHEME_COLUMNS = ("trigger", "compensation", "edge_model", "period_ms")    # effective values, `scheme_columns`
CSV_COLUMNS = ("point", "controller", *SCHEME_COLUMNS, "eta", "r", "link", "delay_ms", "jitter_ms", "loss", "cycles",
               "seed", "downlink_msgs", "downlink_bytes", "uplink_msgs", "total_msgs", "total_bytes",
               "max_err_hip_rad", "max_err_knee_rad", "max_err_rad", "rms_err_hip_rad", "rms_err_knee_rad",
               "rms_err_rad", "latency_p50_us", "latency_p99_us", "wall_s", "status", "error", "config_sha256",
               "verdict", "verdict_reasons")   # the point's summary.json verdict: status, reason codes


LINK_KEYS = ("delay_ms", "jitter_ms", "loss", "link")   # the columns of a sweep row naming its link condition


def link_label(key: tuple[Any, ...]) -> str:
    """A LINK_KEYS group's label: its link spec (`--links`), else the delay/jitter/loss axes' values."""
    if len(key) > 3 and key[3]:
        return str(key[3])
    return f"delay {key[0]:g} ms, jitter {key[1]:g} ms, loss {key[2]:g}"


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
    """A link condition of the grid: delay x jitter x loss axes, or a full link spec (`--links`; the numbers are
    then the spec's, for the CSV)."""
    delay_ms: float
    jitter_ms: float
    loss: float
    spec: str = ""

    @classmethod
    def from_spec(cls, spec: str) -> LinkCondition:
        ov = parse_link_spec(spec)
        return cls(float(ov.get("delay_s", 0.0)) * 1000.0, float(ov.get("jitter_s", 0.0)) * 1000.0,
                   float(ov.get("loss", 0.0)), spec)

    def label(self) -> str:
        if self.spec:
            return self.spec
        return f"delay {self.delay_ms:g} ms, jitter {self.jitter_ms:g} ms, loss {self.loss:g}"

    def overrides(self) -> dict[str, Any]:
        """One direction's `[link.<dir>]` overrides."""
        if self.spec:
            return parse_link_spec(self.spec)
        return {"delay_s": self.delay_ms / 1000.0, "jitter_s": self.jitter_ms / 1000.0, "loss": self.loss}


@dataclass(frozen=True)
class GridPoint:
    """One session of the sweep. TT reference points have eta = r = None (the trigger is not used); `seed` None =
    the sweep's --seed (or the config's) for every point, else this point's seed (the seeds axis); `scheme` the
    trigger placement, compensation and sample period (sea_hil/sweep/methods.py; default: the config's)."""
    index: int
    controller: str
    link: LinkCondition
    eta: float | None = None
    r: float | None = None
    seed: int | None = None
    scheme: Scheme = Scheme()

    @property
    def name(self) -> str:
        trig = f"_eta{self.eta:g}_r{self.r:g}" if self.controller == "et" else ""
        lk = self.link
        seed = "" if self.seed is None else f"_s{self.seed}"
        return (f"p{self.index:03d}_{self.controller}{self.scheme.tag()}{trig}_d{lk.delay_ms:g}_j{lk.jitter_ms:g}"
                f"_l{lk.loss:g}{seed}")

    def label(self) -> str:
        trig = f" eta={self.eta:g} r={self.r:g}" if self.controller == "et" else ""
        seed = "" if self.seed is None else f" | seed {self.seed}"
        scheme = self.scheme.tag().replace("_", " ")
        return f"{self.controller}{scheme}{trig} | {self.link.label()}{seed}"


def expand_grid(eta: Sequence[float], r: Sequence[float], delay_ms: Sequence[float], jitter_ms: Sequence[float],
                loss: Sequence[float], seeds: Sequence[int | None] = (None,), *,
                tt_schemes: Sequence[Scheme] = (Scheme(),), et_schemes: Sequence[Scheme] = (Scheme(),),
                links: Sequence[LinkCondition] | None = None) -> list[GridPoint]:
    """Per link condition (delay x jitter x loss, or `links`) and seed: a TT reference per TT scheme (by default
    one), then every ET point (ET scheme x eta x r)."""
    points: list[GridPoint] = []
    conditions = links if links is not None else [LinkCondition(d, j, lo) for d, j, lo in
                                                  itertools.product(delay_ms, jitter_ms, loss)]
    for link in conditions:
        for seed in seeds:
            for sch in tt_schemes:
                points.append(GridPoint(len(points), "tt", link, seed=seed, scheme=sch))
            for sch, e, rr in itertools.product(et_schemes, eta, r):
                points.append(GridPoint(len(points), "et", link, e, rr, seed, sch))
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
    one = point.link.overrides()
    dirs = ("uplink", "downlink") if direction == "both" else (direction,)
    ov: dict[str, Any] = {"link": {d: dict(one) for d in dirs}, **point.scheme.overrides()}
    if point.controller == "et":
        ov["trigger"] = {**ov.get("trigger", {}), "eta": point.eta, "r": point.r}
    else:   # a TT reference is periodic both ways: a state up and a setpoint down every sample, whatever the config
        ov["trigger"] = {**ov.get("trigger", {}), "placement": "controller"}
    return ov


def scheme_columns(cfg: Any) -> dict[str, Any]:
    """The CSV's SCHEME_COLUMNS of a point's effective config."""
    edge = cfg.trigger.placement == "edge"     # edge_model is used by the trigger at the edge only
    return {"trigger": cfg.trigger.placement, "compensation": cfg.controller.compensation,
            "edge_model": edge and cfg.trigger.edge_model,
            "period_ms": round(cfg.controller.sample_period_s * 1000.0, 6)}


def point_command(point: GridPoint, mode: str, cfg_path: Path, out: Path, cycles: int,
                  python: str = "python3") -> list[str]:
    """The `sea-hil run --lockstep` command line of one point (engine lockstep)."""
    if mode != "lockstep":
        raise ConfigError(f"only the lockstep engine runs a point as a process, not {mode!r}")
    return [python, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--no-figures"] + [
        "--controller", point.controller, "--config", str(cfg_path), "--cycles", str(cycles), "--out", str(out)]


def _tx(summary: dict[str, Any]) -> dict[str, Any]:
    t = summary.get("transmissions") or {}
    return {k: t.get(k, "") for k in ("downlink_msgs", "downlink_bytes", "uplink_msgs", "total_msgs", "total_bytes")}


def csv_row(point: GridPoint, summary: dict[str, Any] | None, *, cycles: int, seed: int, wall_s: float,
            status: str = "ok", error: str = "", config_sha256: str = "",
            scheme: dict[str, Any] | None = None) -> dict[str, Any]:
    """One CSV row (keys = CSV_COLUMNS); `summary` is the point's summary.json (None if the point failed), `scheme`
    the point's `scheme_columns`."""
    row: dict[str, Any] = {c: "" for c in CSV_COLUMNS}
    row.update(scheme or {})
    row.update(point=point.name, controller=point.controller, eta="" if point.eta is None else point.eta,
               r="" if point.r is None else point.r, link=point.link.spec, delay_ms=point.link.delay_ms,
               jitter_ms=point.link.jitter_ms,
               loss=point.link.loss, cycles=cycles, seed=seed, wall_s=round(wall_s, 3), status=status,
               error=" ".join(error.split()), config_sha256=config_sha256)
    if summary is None:
        return row
    row.update(_tx(summary))
    v = summary.get("verdict") or {}
    row.update(verdict=v.get("status", ""), verdict_reasons=" ".join(sorted({r["code"] for r in v.get("reasons", [])})))
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
