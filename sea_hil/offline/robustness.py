"""`sea-hil robustness`: offline closed loop over disturbance amplitude and nominal-model mismatch, TT and ET.

Disturbance axis: each kind (constant, 0.5 Hz sine, 2 Hz sine, 10 ms held noise) on both joints at once, scaled from
0 to the issue-15 design amplitudes (0.5 N m hip, 0.05 N m knee). Mismatch axis: the controller's masses, inertias or
spring constants off by -20 .. +20 % (`--mismatch GROUP=P%`). Every point is one offline `simulate` (CAN quantisation
on, as the networked path), so the whole grid is deterministic and takes seconds.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sea_hil.config.shorthand import scenario_config
from sea_hil.offline.closed_loop import simulate

HIP_NM, KNEE_NM = 0.5, 0.05
KINDS = {"constant": "constant:{a}Nm", "sine 0.5 Hz": "sine:{a}Nm@0.5Hz", "sine 2 Hz": "sine:{a}Nm@2Hz",
         "noise": "noise:{a}Nm@10ms"}
GROUPS = ("mass", "inertia", "stiffness")
SCALES = (0.0, 0.25, 0.5, 0.75, 1.0)
PERCENTS = (-20.0, -10.0, 0.0, 10.0, 20.0)


@dataclass(frozen=True)
class Point:
    axis: str      # "disturbance" or "mismatch"
    series: str    # disturbance kind or mismatch group
    value: float   # amplitude scale (1 = 0.5 / 0.05 N m) or percent
    disturbance: str | None
    mismatch: str | None


def grid(scales: tuple[float, ...] = SCALES, percents: tuple[float, ...] = PERCENTS) -> list[Point]:
    pts = []
    for kind, fmt in KINDS.items():
        for s in scales:
            spec = f"hip={fmt.format(a=HIP_NM * s)},knee={fmt.format(a=KNEE_NM * s)}" if s else None
            pts.append(Point("disturbance", kind, s, spec, None))
    for group in GROUPS:
        for pc in percents:
            pts.append(Point("mismatch", group, pc, None, f"{group}={pc:+g}%" if pc else None))
    return pts


def run_point(pt: Point, mode: str, config: str | None, overrides: dict[str, Any], settle_s: float = 0.0
              ) -> dict[str, Any]:
    """One offline run; errors over the samples at t >= settle_s (the offline start is a transient of its own:
    the plant starts on the trajectory at the static nut balance, docs/deviations.md section 6)."""
    cfg = scenario_config(config, overrides, pt.disturbance, pt.mismatch)
    res = simulate(cfg, mode, quantise=True)
    err = np.abs(res.theta_rad - res.desired_rad)[res.t_s >= settle_s]
    return {"axis": pt.axis, "series": pt.series, "value": pt.value, "controller": mode,
            "disturbance": pt.disturbance or "", "mismatch": pt.mismatch or "",
            "max_err_hip_rad": float(err[:, 0].max()), "max_err_knee_rad": float(err[:, 1].max()),
            "rms_err_hip_rad": float(np.sqrt((err[:, 0] ** 2).mean())),
            "rms_err_knee_rad": float(np.sqrt((err[:, 1] ** 2).mean())),
            "transmissions": int(len(res.event_t_s)),
            "saturated_fraction": res.saturated_steps / res.inner_steps}


def run_grid(points: list[Point], config: str | None, overrides: dict[str, Any], settle_s: float = 0.0,
             log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    rows = []
    for i, pt in enumerate(points):
        for mode in ("tt", "et"):
            rows.append(run_point(pt, mode, config, overrides, settle_s))
        log(f"[{i + 1:2d}/{len(points)}] {pt.axis} {pt.series} {pt.value:g}: TT max "
            f"{max(rows[-2]['max_err_hip_rad'], rows[-2]['max_err_knee_rad']):.4f} rad, ET max "
            f"{max(rows[-1]['max_err_hip_rad'], rows[-1]['max_err_knee_rad']):.4f} rad, "
            f"{rows[-1]['transmissions']}/{rows[-2]['transmissions']} setpoints")
    return rows
