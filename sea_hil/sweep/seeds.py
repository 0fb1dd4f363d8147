"""The seeds axis in figures: rows of the same grid point under different seeds folded into one mean row with a
95 % confidence half-width (Student t), so a figure shows the mean and its band while sweep.csv keeps every seed."""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from scipy import stats

MEAN_COLUMNS = ("downlink_msgs", "total_msgs", "max_err_rad", "rms_err_rad", "max_err_hip_rad", "max_err_knee_rad")


def _group_key(row: dict[str, Any]) -> tuple:
    return (row["controller"], row["eta"], row["r"], row["delay_ms"], row["jitter_ms"], row["loss"], row["cycles"],
            *(row.get(k, "") for k in ("link", "trigger", "compensation", "edge_model", "period_ms")))


def ci95_half_width(values: Sequence[float]) -> float:
    """Half-width of the 95 % confidence interval of the mean (0 for fewer than two values)."""
    n = len(values)
    if n < 2:
        return 0.0
    mean = sum(values) / n
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    return float(stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n))


def fold_seeds(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per grid point over its ok seeds: the first seed's row with MEAN_COLUMNS replaced by their means,
    plus `n_seeds` and `<column>_ci95` half-widths. Rows that are not ok pass through unchanged."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    out: list[dict[str, Any]] = []
    for r in rows:
        if r["status"] != "ok" or any(r[c] == "" for c in ("downlink_msgs", "max_err_rad")):
            out.append(r)
        else:
            groups.setdefault(_group_key(r), []).append(r)
    for members in groups.values():
        folded = dict(members[0], n_seeds=len(members))
        for c in MEAN_COLUMNS:
            vals = [float(m[c]) for m in members if m.get(c, "") != ""]
            if vals:
                folded[c] = sum(vals) / len(vals)
                folded[f"{c}_ci95"] = ci95_half_width(vals)
        out.append(folded)
    return out
