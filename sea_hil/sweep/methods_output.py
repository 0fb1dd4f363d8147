"""`sea-hil sweep`'s method comparison (issue 16): DIR/methods.png — total link messages (states up + setpoints
down) per walking cycle against max tracking error, one panel per link condition, one curve per method (TT per
compensation over its sample periods; ET per trigger placement / compensation / edge model over its thresholds),
seeds folded into their mean with the 95 % band — and the sweep.md section judging every ET point against
periodic TT at the same total messages (`sea_hil.sweep.frontier`)."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sea_hil.sweep.frontier import OutsideBaseline, dominates  # noqa: E402
from sea_hil.sweep.grid import LINK_KEYS, link_label  # noqa: E402
from sea_hil.sweep.seeds import fold_seeds  # noqa: E402


def method_label(row: dict[str, Any]) -> str:
    """The curve a row belongs to: TT by compensation; ET by placement, compensation and edge model."""
    if row["controller"] == "tt":
        return f"TT, compensation {row.get('compensation') or '?'}"
    model = " + model" if str(row.get("edge_model")) == "True" and row.get("trigger") == "edge" else ""
    return f"ET, trigger at {row.get('trigger') or '?'}{model}, compensation {row.get('compensation') or '?'}"


def _xy(row: dict[str, Any]) -> tuple[float, float]:
    return float(row["total_msgs"]) / float(row["cycles"]), float(row["max_err_rad"])


def curves_by_link(rows: Sequence[dict[str, Any]]) -> dict[tuple, dict[str, list[dict[str, Any]]]]:
    """link key -> method label -> its ok rows (seeds folded), sorted by total messages."""
    out: dict[tuple, dict[str, list[dict[str, Any]]]] = {}
    for r in fold_seeds(rows):
        if r["status"] != "ok" or r.get("total_msgs", "") == "" or r["max_err_rad"] == "":
            continue
        key = tuple(r.get(k, "") for k in LINK_KEYS)
        out.setdefault(key, {}).setdefault(method_label(r), []).append(r)
    for methods in out.values():
        for pts in methods.values():
            pts.sort(key=_xy)
    return dict(sorted(out.items()))


def compares_methods(rows: Sequence[dict[str, Any]]) -> bool:
    """True when the rows hold more than one scheme (trigger placement, compensation, edge model, outer period): a
    method comparison to draw. A plain eta/r/link sweep (one scheme; TT and ET are in pareto.png) has none."""
    keys = ("trigger", "compensation", "edge_model", "period_ms")
    return len({tuple(str(r.get(k)) for k in keys) for r in rows}) > 1


def methods_figure(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    curves = curves_by_link(rows)
    n = max(len(curves), 1)
    cols = min(n, 2)
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(7.5 * cols, 5.5 * ((n + cols - 1) // cols)),
                             squeeze=False)
    labels = sorted({m for methods in curves.values() for m in methods})
    colours = dict(zip(labels, plt.rcParams["axes.prop_cycle"].by_key()["color"] * 4, strict=False))
    for ax, (key, methods) in zip(axes.flat, curves.items(), strict=False):
        for label, pts in sorted(methods.items()):
            xs, ys = zip(*(_xy(p) for p in pts), strict=True)
            marker = "s" if label.startswith("TT") else "o"
            ax.plot(xs, ys, "-" + marker, color=colours[label], label=label, ms=5)
            if any(p.get("n_seeds", 1) > 1 for p in pts):    # mean over seeds: 95 % band of both coordinates
                ax.errorbar(xs, ys, xerr=[p.get("total_msgs_ci95", 0.0) / float(p["cycles"]) for p in pts],
                            yerr=[p.get("max_err_rad_ci95", 0.0) for p in pts], fmt="none", ecolor=colours[label],
                            alpha=0.5, capsize=2)
            if label.startswith("TT"):
                for p, x, y in zip(pts, xs, ys, strict=True):
                    ax.annotate(f"{p['period_ms']:g} ms", (x, y), textcoords="offset points", xytext=(3, 3),
                                fontsize=6, color=colours[label])
        ax.set_yscale("log")
        ax.set(title=link_label(key), xlabel="total link messages (states up + setpoints down) per walking cycle",
               ylabel="max |tracking error| over both joints [rad]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(curves):]:
        ax.set_visible(False)
    fig.suptitle("sea-hil sweep: traffic against tracking error per method (TT labelled with its sample period)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def domination_markdown(rows: Sequence[dict[str, Any]]) -> list[str]:
    """sweep.md lines: per link, every ET point's total messages and max error against each TT curve's error at
    the same total (linear between periods; "outside" beyond TT's range), and whether ET's is at most half."""
    lines = ["## Methods: total link messages against periodic TT at the same traffic", "",
             "Per link: each ET point against each TT curve, TT's max error linearly interpolated between its sample "
             "periods at ET's total messages (`sea_hil/sweep/frontier.py`); figure `methods.png`.", ""]
    for key, methods in curves_by_link(rows).items():
        tt = {m: [_xy(p) for p in pts] for m, pts in methods.items() if m.startswith("TT")}
        lines.append(f"- **{link_label(key)}**")
        for label, pts in methods.items():
            if label.startswith("TT"):
                lines.append(f"  - {label}: " + ", ".join(f"{p['period_ms']:g} ms {x:g} msgs {y:.4f} rad"
                                                          for p, (x, y) in zip(pts, map(_xy, pts), strict=True)))
                continue
            for p in pts:
                x, y = _xy(p)
                verdicts = []
                for tt_label, curve in tt.items():
                    try:
                        ok, tt_err = dominates(x, y, curve)
                        verdicts.append(f"{tt_label}: {tt_err:.4f} rad, {'<=' if ok else 'NOT <='} half")
                    except OutsideBaseline:
                        verdicts.append(f"{tt_label}: outside its periods")
                lines.append(f"  - {label} η={p['eta']:g} r={p['r']:g}: {x:g} msgs, {y:.4f} rad; TT at the same "
                             f"msgs: " + ("; ".join(verdicts) or "no TT curve"))
    return lines + [""]
