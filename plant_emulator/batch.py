"""One compiled integration step for every limb of a bus: the driver node (`PlantNode`) integrates the period of all
its drivers (`DriverCore`) in one numba call instead of one `advance` call per limb.

Each driver's period is a list of pieces of constant voltage (`DriverCore.segments`); the batch kernel runs the
pieces of every limb, in order, on one state array (N x 8), with the same RK4 sub-step code (`rk4_core`) and the same
arithmetic as `advance`'s kernel (`h = dt / n`, sub-step i at `t + i * h`), so a limb's state after the batch step
is bit for bit the state `DriverCore.step` gives it alone (tests/test_batch_step.py). The disturbance torques are
sampled here in Python, exactly where `advance` samples them. Without a loaded kernel (lockstep, which does not warm
numba up; numba not installed) `step_all` runs `DriverCore.step` per driver: the same floats.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from sea_hil.dynamics import rk4_core
from sea_hil.jit import compiled, loaded
from sea_hil.mechanics import LimbParams
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.protocol.can_frames import Feedback


def make_batch_kernel(fingerprint: str = "") -> Callable[..., None]:
    """The batch kernel's factory (`sea_hil.jit.compiled`). Piece j integrates limb `limb[j]` (row of `xs`, updated
    in place) from `t[j]` over `dt[j]` in `n[j]` sub-steps with voltage `u[j]`; its disturbance values start at
    `dist[doff[j]]`: d(t_i), d(t_i + h/2), d(t_i + h) of each sub-step i, 6 floats per sub-step."""

    def batch_kernel(xs, limb, t, dt, n, u, dist, doff, p):  # type: ignore[no-untyped-def]
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        for j in range(limb.shape[0]):
            i = limb[j]
            x = (xs[i, 0], xs[i, 1], xs[i, 2], xs[i, 3], xs[i, 4], xs[i, 5], xs[i, 6], xs[i, 7])
            uj = (u[j, 0], u[j, 1])
            nj = n[j]
            h = dt[j] / nj
            for k in range(nj):
                m = doff[j] + 6 * k
                x = rk4_core(t[j] + k * h, x, uj, h, p, (dist[m], dist[m + 1]), (dist[m + 2], dist[m + 3]),
                             (dist[m + 4], dist[m + 5]))
            for c in range(8):
                xs[i, c] = x[c]

    return batch_kernel


def prepare_batch(p: LimbParams, jit: bool = True) -> bool:
    """Load (or compile) the batch kernel now, before a real-time schedule starts; False without numba."""
    kernel = compiled(make_batch_kernel) if jit else None
    if kernel is not None:
        kernel(np.zeros((1, 8)), np.zeros(1, np.int64), np.zeros(1), np.full(1, 1e-3), np.ones(1, np.int64),
               np.zeros((1, 2)), np.zeros(6), np.zeros(1, np.int64), p)
    return kernel is not None


def step_all(drivers: Sequence[DriverCore], *, jit: bool = True) -> list[Feedback]:
    """Integrate one period of every driver (all with the same `params`) and return their new samples' feedback,
    in order: one batch-kernel call when it is loaded, else `DriverCore.step` per driver."""
    kernel = loaded(make_batch_kernel) if jit and len(drivers) > 1 else None
    if kernel is None:
        return [drv.step() for drv in drivers]
    limb: list[int] = []
    t: list[float] = []
    dt: list[float] = []
    n: list[int] = []
    u: list[tuple[float, float]] = []
    doff: list[int] = []
    dist: list[float] = []
    for i, drv in enumerate(drivers):
        d = drv.disturbance
        for t_s, dt_s, steps, volts in drv.segments():
            limb.append(i)
            t.append(t_s)
            dt.append(dt_s)
            n.append(steps)
            u.append(volts)
            doff.append(len(dist))
            h = dt_s / steps
            hh = 0.5 * h
            for k in range(steps):   # where `advance` samples d(t): t_k, t_k + h/2, t_k + h
                tk = t_s + k * h
                dist += (*d(tk), *d(tk + hh), *d(tk + h))
    xs = np.array([drv.x for drv in drivers], dtype=np.float64)
    kernel(xs, np.array(limb, np.int64), np.array(t), np.array(dt), np.array(n, np.int64), np.array(u),
           np.array(dist if dist else [0.0]), np.array(doff, np.int64), drivers[0].params)
    return [drv.finish_period(_state(row)) for drv, row in zip(drivers, xs.tolist())]


def _state(row: list[Any]) -> Any:
    return tuple(row)
