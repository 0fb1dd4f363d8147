"""`sea-hil sweep` outputs: DIR/pareto.png (transmissions vs max tracking error, Pareto front per
link condition, TT references and the paper's points marked), DIR/methods.png (sea_hil/sweep/methods_output.py) and
DIR/sweep.md."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sea_hil.report.summary import PAPER  # noqa: E402
from sea_hil.sweep.grid import LINK_KEYS, link_label, pareto_front  # noqa: E402
from sea_hil.sweep.methods_output import compares_methods, domination_markdown, methods_figure  # noqa: E402
from sea_hil.sweep.seeds import fold_seeds  # noqa: E402

METRICS = {"max_err_rad": "max |tracking error| over both joints [rad]",
           "rms_err_rad": "RMS tracking error (worse joint) [rad]"}


def _plottable(rows: Sequence[dict[str, Any]], metric: str) -> list[dict[str, Any]]:
    return [r for r in rows if r["status"] == "ok" and r["downlink_msgs"] != "" and r[metric] != ""]


def _xy(row: dict[str, Any], metric: str = "max_err_rad") -> tuple[float, float]:
    """(downlink transmissions per walking cycle, the error metric)."""
    return float(row["downlink_msgs"]) / float(row["cycles"]), float(row[metric])


def fronts_by_link(rows: Sequence[dict[str, Any]],
                   metric: str = "max_err_rad") -> dict[tuple, list[tuple[dict[str, Any], bool]]]:
    """Successful rows grouped by link condition, each with its Pareto flag within that group (TT included); rows
    of one grid point under several seeds are folded into their mean first (`sea_hil.sweep.seeds`)."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in _plottable(fold_seeds(rows), metric):
        groups.setdefault(tuple(r.get(k, "") for k in LINK_KEYS), []).append(r)
    return {k: list(zip(g, pareto_front([_xy(r, metric) for r in g]), strict=True)) for k, g in groups.items()}


def _front_labels(flagged: list[tuple[dict[str, Any], bool]], metric: str) -> dict[tuple[float, float], str]:
    """One label per distinct front position; coinciding points (e.g. ET sending every sample = TT) share it."""
    names: dict[tuple[float, float], list[str]] = {}
    for row, on_front in flagged:
        if on_front:
            tag = "TT" if row["controller"] == "tt" else f"η={row['eta']:g} r={row['r']:g}"
            names.setdefault(_xy(row, metric), []).append(tag)
    def short(tags: list[str]) -> str:
        et = sorted(t for t in tags if t != "TT")
        if "TT" in tags:
            return f"TT = {len(et)} ET" if et else "TT"
        return et[0] + (f" (+{len(et) - 1} ET)" if len(et) > 1 else "")
    return {xy: short(tags) for xy, tags in names.items()}


def _panel(ax: Any, rows: Sequence[dict[str, Any]], metric: str, paper: bool) -> None:
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for n, (key, flagged) in enumerate(sorted(fronts_by_link(rows, metric).items())):
        c = colours[n % len(colours)]
        groups: dict[tuple[str, bool], list[tuple[float, float]]] = {}
        for row, on_front in flagged:       # one artist per marker kind (a grid has thousands of points)
            x, y = _xy(row, metric)
            groups.setdefault(("s" if row["controller"] == "tt" else "o", on_front), []).append((x, y))
            if row.get("n_seeds", 1) > 1:    # mean over seeds: 95 % confidence band of both coordinates
                ax.errorbar(x, y, xerr=row["downlink_msgs_ci95"] / float(row["cycles"]),
                            yerr=row.get(f"{metric}_ci95", 0.0), fmt="none", ecolor=c, alpha=0.5, capsize=2)
        for (marker, on_front), pts in groups.items():
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker, ls="none", ms=9 if marker == "s" else 7,
                    mec=c, mfc=c if on_front else "none", mew=1.5)
        for (x, y), text in _front_labels(flagged, metric).items():
            ax.annotate(text, (x, y), textcoords="offset points", xytext=(-6, 5), ha="right", fontsize=7, color=c)
        front = sorted(_xy(r, metric) for r, f in flagged if f)
        ax.plot([p[0] for p in front], [p[1] for p in front], "-", color=c, alpha=0.7, label=link_label(key))
    if paper:
        for mode, marker in (("tt", "X"), ("et", "*")):
            p = PAPER[mode]
            ax.plot(p["transmissions"], p["max_abs_error_rad"], marker, color="black", ms=13, ls="none",
                    label=f"paper {mode.upper()} ({p['transmissions']}, {p['max_abs_error_rad']} rad)")
    ax.plot([], [], "o", color="grey", mfc="none", label="ET point (filled = on the Pareto front)")
    ax.plot([], [], "s", color="grey", label="TT reference (same link)")
    if any(r.get("n_seeds", 1) > 1 for r in fold_seeds(rows)):
        ax.errorbar([], [], yerr=[], fmt="none", ecolor="grey", label="mean over seeds, 95 % confidence")
    ax.set_yscale("log")
    ax.set(xlabel="downlink transmissions (setpoints) per walking cycle", ylabel=METRICS[metric])
    ax.grid(True, which="both", alpha=0.3)
    # "best" searches every artist for the emptiest corner: fine for a few link conditions, seconds for a grid's
    ax.legend(fontsize=7, loc="best" if len(ax.get_lines()) < 200 else "upper right")


def pareto_figure(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Left: max error (the paper's measure, its two points marked); right: RMS error. Line = Pareto front per
    link condition (filled markers), both axes minimised."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(15, 6))
    _panel(ax1, rows, "max_err_rad", paper=True)
    _panel(ax2, rows, "rms_err_rad", paper=False)
    ax1.set_title("transmissions vs max tracking error (paper's measure)")
    ax2.set_title("transmissions vs RMS tracking error")
    fig.suptitle("sea-hil sweep: Pareto front per link condition")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(v: Any, spec: str) -> str:
    return format(v, spec) if isinstance(v, (int, float)) else str(v)


def sweep_markdown(rows: Sequence[dict[str, Any]], command: str, wall_s: float, jobs: int, mode: str,
                   interrupted: bool) -> str:
    ok = sum(r["status"] == "ok" for r in rows)
    lines = ["# sea-hil sweep", "", f"Command: `{command}`", "",
             f"{len(rows)} points ({ok} ok{', INTERRUPTED' if interrupted else ''}), mode {mode}, {jobs} parallel "
             f"jobs, total wall time {wall_s:.1f} s. Figures: `pareto.png`, `methods.png`; all numbers: `sweep.csv`; "
             "per point: `points/<point>/`.", "",
             f"Paper (one walking cycle): TT {PAPER['tt']['transmissions']} transmissions, max error "
             f"~{PAPER['tt']['max_abs_error_rad']} rad; ET {PAPER['et']['transmissions']} transmissions, "
             f"~{PAPER['et']['max_abs_error_rad']} rad.", "", "## Pareto front per link condition", ""]
    for key, flagged in sorted(fronts_by_link(rows).items()):
        front = sorted((r for r, f in flagged if f), key=_xy)
        pts = ", ".join(f"{r['controller'].upper()}"
                        + (f" η={r['eta']:g} r={r['r']:g}" if r["controller"] == "et" else "")
                        + f" ({_xy(r)[0]:g} tx/cycle, {_xy(r)[1]:.4f} rad)" for r in front)
        lines.append(f"- {link_label(key)}: {pts}")
    lines += ["", "## All points", "",
              "| point | ctrl | trigger / compensation / period ms | eta | r | delay ms | jitter ms | loss | "
              "downlink msgs | total msgs | max err hip / knee [rad] | latency p99 [us] | wall [s] | status |", "|" + "---|" * 14]
    for r in rows:
        status = r["status"] + (f": {r['error']}" if r["error"] else "")
        scheme = f"{r.get('trigger', '')} / {r.get('compensation', '')} / {_fmt(r.get('period_ms', ''), 'g')}"
        lines.append(f"| {r['point']} | {r['controller']} | {scheme} | {_fmt(r['eta'], 'g')} | {_fmt(r['r'], 'g')} | "
                     f"{r['delay_ms']:g} | {r['jitter_ms']:g} | {r['loss']:g} | {r['downlink_msgs']} | "
                     f"{r.get('total_msgs', '')} | "
                     f"{_fmt(r['max_err_hip_rad'], '.4f')} / {_fmt(r['max_err_knee_rad'], '.4f')} | "
                     f"{_fmt(r['latency_p99_us'], '.0f')} | {r['wall_s']:.1f} | {status.replace('|', '/')} |")
    return "\n".join(lines) + "\n"


def write_outputs(out: Path, rows: Sequence[dict[str, Any]], command: str, wall_s: float, jobs: int, mode: str,
                  interrupted: bool) -> None:
    """pareto.png, methods.png (when the rows compare methods: `compares_methods`) and sweep.md (sweep.csv is written
    by the runner as points finish, `sea_hil.sweep.csvlog`)."""
    out.mkdir(parents=True, exist_ok=True)
    pareto_figure(out / "pareto.png", rows)
    if compares_methods(rows):
        methods_figure(out / "methods.png", rows)
    md = sweep_markdown(rows, command, wall_s, jobs, mode, interrupted)
    (out / "sweep.md").write_text(md + "\n" + "\n".join(domination_markdown(rows)), encoding="utf-8")
