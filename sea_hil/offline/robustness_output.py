"""Outputs of `sea-hil robustness`: robustness.csv, robustness.png (max / RMS error and ET transmissions against
disturbance amplitude and against mismatch, TT and ET) and robustness.md."""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sea_hil.offline.robustness import HIP_NM, KNEE_NM  # noqa: E402

FIELDS = ("axis", "series", "value", "controller", "disturbance", "mismatch", "max_err_hip_rad", "max_err_knee_rad",
          "rms_err_hip_rad", "rms_err_knee_rad", "transmissions", "saturated_fraction")
BOUND_RAD = 0.01


def _max(r: dict[str, Any]) -> float:
    return max(r["max_err_hip_rad"], r["max_err_knee_rad"])


def _rms(r: dict[str, Any]) -> float:
    return max(r["rms_err_hip_rad"], r["rms_err_knee_rad"])


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)


def write_figure(path: Path, rows: list[dict[str, Any]]) -> None:
    """3 rows (max error, RMS error, transmissions) x 2 columns (disturbance, mismatch); TT solid, ET dashed."""
    fig, axes = plt.subplots(3, 2, figsize=(12, 10), sharex="col")
    for col, axis in enumerate(("disturbance", "mismatch")):
        sub = [r for r in rows if r["axis"] == axis]
        for i, series in enumerate(dict.fromkeys(r["series"] for r in sub)):
            color = f"C{i}"
            for mode, style in (("tt", "-"), ("et", "--")):
                pts = sorted((r for r in sub if r["series"] == series and r["controller"] == mode),
                             key=lambda r: r["value"])
                x = [r["value"] for r in pts]
                label = f"{series} {mode.upper()}"
                axes[0, col].plot(x, [_max(r) for r in pts], style, color=color, marker="o", ms=3, label=label)
                axes[1, col].plot(x, [_rms(r) for r in pts], style, color=color, marker="o", ms=3, label=label)
                axes[2, col].plot(x, [r["transmissions"] for r in pts], style, color=color, marker="o", ms=3,
                                  label=label)
        axes[0, col].axhline(BOUND_RAD, color="k", lw=0.8, ls=":", label="0.01 rad")
        axes[0, col].set(ylabel="max error (worse joint) [rad]", yscale="log",
                         title=f"against {axis}" + (f" (1 = {HIP_NM} N m hip, {KNEE_NM} N m knee, both)"
                                                   if axis == "disturbance" else " of the nominal model"))
        axes[1, col].set(ylabel="RMS error (worse joint) [rad]", yscale="log")
        axes[2, col].set(ylabel="setpoints sent", xlabel="amplitude scale" if axis == "disturbance" else
                         "controller's model - plant [%]")
        for ax in axes[:, col]:
            ax.grid(True, alpha=0.3)
        axes[0, col].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_markdown(path: Path, rows: list[dict[str, Any]], command: str) -> None:
    lines = ["# Robustness (offline, CAN-quantised, one cycle, errors after --settle-s)", "", f"`{command}`", "",
             "| axis | series | value | TT max / RMS [rad] | ET max / RMS [rad] | ET / TT setpoints | "
             "saturated TT / ET |", "|---|---|---|---|---|---|---|"]
    pairs: dict[tuple[str, str, float], dict[str, dict[str, Any]]] = {}
    for r in rows:
        pairs.setdefault((r["axis"], r["series"], r["value"]), {})[r["controller"]] = r
    for (axis, series, value), pr in pairs.items():
        tt, et = pr["tt"], pr["et"]
        unit = f"{value:g}" if axis == "disturbance" else f"{value:+g} %"
        lines.append(f"| {axis} | {series} | {unit} | {_max(tt):.4f} / {_rms(tt):.4f} | {_max(et):.4f} / "
                     f"{_rms(et):.4f} | {et['transmissions']} / {tt['transmissions']} | "
                     f"{100 * tt['saturated_fraction']:.2f} / {100 * et['saturated_fraction']:.2f} % |")
    met = sum(_max(r) <= BOUND_RAD for r in rows)
    lines += ["", f"{met} of {len(rows)} runs within {BOUND_RAD} rad max error.", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
