"""Figures shared by `simulate`, `run` and `report`: the paper's Fig. 2-4 and the network plots."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

JOINTS = ("hip (theta1)", "knee (theta2)")


def tracking_figure(path: Path, t_s: np.ndarray, theta_rad: np.ndarray, desired_rad: np.ndarray, title: str) -> None:
    """Paper Fig. 2/3: angles vs desired (left) and tracking errors (right)."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for j, name in enumerate(JOINTS):
        ax1.plot(t_s, desired_rad[:, j], "--", label=f"desired {name}")
        ax1.plot(t_s, theta_rad[:, j], label=f"actual {name}")
        ax2.plot(t_s, theta_rad[:, j] - desired_rad[:, j], label=name)
    ax1.set(xlabel="time [s]", ylabel="angle [rad]", title=f"{title}: joint angles")
    ax2.set(xlabel="time [s]", ylabel="error [rad]", title=f"{title}: tracking errors")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    _save(fig, path)


def inter_event_figure(path: Path, event_t_s: np.ndarray, title: str) -> None:
    """Paper Fig. 4: inter-event time at each event."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    if len(event_t_s) > 1:
        ax.stem(event_t_s[1:], np.diff(event_t_s), basefmt=" ")
    ax.set(xlabel="time [s]", ylabel="inter-event time [s]", title=f"{title}: inter-event times")
    ax.grid(True, alpha=0.3)
    _save(fig, path)


def histogram_cdf_figure(path: Path, values: np.ndarray, xlabel: str, title: str) -> None:
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.5))
    if len(values):
        ax1.hist(values, bins=50)
        xs = np.sort(values)
        ax2.plot(xs, np.arange(1, len(xs) + 1) / len(xs))
    ax1.set(xlabel=xlabel, ylabel="count", title=f"{title}: histogram")
    ax2.set(xlabel=xlabel, ylabel="CDF", title=f"{title}: CDF")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
    _save(fig, path)


def series_figure(path: Path, t_s: np.ndarray, series: dict[str, np.ndarray], ylabel: str, title: str) -> None:
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for name, ys in series.items():
        ax.plot(t_s[: len(ys)], ys, label=name)
    ax.set(xlabel="time [s]", ylabel=ylabel, title=title)
    ax.grid(True, alpha=0.3)
    if series:
        ax.legend(fontsize=8)
    _save(fig, path)


def _save(fig: Any, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
