"""One compiled integration step for every limb of a bus: the driver node (`PlantNode`) integrates the period of all
its drivers (`DriverCore`) in one numba call instead of one `advance` call per limb.

Each driver's period is a list of pieces of constant voltage (`DriverCore.segments`); the batch kernel runs the
pieces of every limb, in order, on one state array (N x 8), with the same RK4 sub-step code (`rk4_core`) and the same
arithmetic as `advance`'s kernel (`h = dt / n`, sub-step i at `t + i * h`), so a limb's state after the batch step
is bit for bit the state `DriverCore.step` gives it alone (tests/test_batch_step.py); the kernel also computes the
feedback's spring deflections (`deflections`, compiled from the same source). The disturbance torques are
sampled here in Python, exactly where `advance` samples them. Without a loaded kernel (lockstep, which does not warm
numba up; numba not installed) `step_all` runs `DriverCore.step` per driver: the same floats.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from sea_hil.dynamics import deflections, rk4_core
from sea_hil.jit import compiled, loaded
from sea_hil.mechanics import LimbParams
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import entry_point
from sea_hil.protocol.can_frames import Feedback


def make_batch_kernel(fingerprint: str = "") -> Callable[..., None]:
    """The batch kernel's factory (`sea_hil.jit.compiled`). Piece j (`segf[j]` = start time, length, voltage 1 and 2;
    `segi[j]` = limb, sub-steps, offset of its disturbance values) integrates row `segi[j, 0]` of `xs` in place; its
    disturbance values start at `dist[segi[j, 2]]`: d(t_i), d(t_i + h/2), d(t_i + h) of each sub-step i, 6 floats
    per sub-step. Then each row's spring deflections go to `delta` (N x 2), as `deflections` gives them."""

    def batch_kernel(xs, segf, segi, dist, p, delta):  # type: ignore[no-untyped-def]
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        for j in range(segi.shape[0]):
            i = segi[j, 0]
            x = (xs[i, 0], xs[i, 1], xs[i, 2], xs[i, 3], xs[i, 4], xs[i, 5], xs[i, 6], xs[i, 7])
            uj = (segf[j, 2], segf[j, 3])
            nj = segi[j, 1]
            t = segf[j, 0]
            h = segf[j, 1] / nj
            for k in range(nj):
                m = segi[j, 2] + 6 * k
                x = rk4_core(t + k * h, x, uj, h, p, (dist[m], dist[m + 1]), (dist[m + 2], dist[m + 3]),
                             (dist[m + 4], dist[m + 5]))
            for c in range(8):
                xs[i, c] = x[c]
        for i in range(xs.shape[0]):
            d = deflections((xs[i, 0], xs[i, 1], xs[i, 2], xs[i, 3], xs[i, 4], xs[i, 5], xs[i, 6], xs[i, 7]), p)
            delta[i, 0] = d[0]
            delta[i, 1] = d[1]

    return batch_kernel


def prepare_batch(p: LimbParams, jit: bool = True) -> bool:
    """Load (or compile) the batch kernel now, before a real-time schedule starts; False without numba."""
    kernel = compiled(make_batch_kernel) if jit else None
    if kernel is not None:
        kernel(np.zeros((1, 8)), np.array([[0.0, 1e-3, 0.0, 0.0]]), np.array([[0, 1, 0]], np.int64), np.zeros(6), p,
               np.zeros((1, 2)))
    return kernel is not None


def _entry(kernel: Callable[..., None], p: LimbParams) -> Callable[..., None]:
    return entry_point(kernel, p, _batch_signature)


def _batch_signature(p_type: object) -> tuple[object, ...]:
    from numba import types

    f64, arr = types.float64, types.Array
    return (arr(f64, 2, "C"), arr(f64, 2, "C"), arr(types.int64, 2, "C"), arr(f64, 1, "C"), p_type, arr(f64, 2, "C"))


def step_all(drivers: Sequence[DriverCore], *, jit: bool = True) -> list[Feedback]:
    """Integrate one period of every driver (all with the same `params`) and return their new samples' feedback,
    in order: one batch-kernel call when it is loaded, else `DriverCore.step` per driver."""
    kernel = loaded(make_batch_kernel) if jit and len(drivers) > 1 else None
    if kernel is None:
        return [drv.step() for drv in drivers]
    segf: list[tuple[float, float, float, float]] = []
    segi: list[tuple[int, int, int]] = []
    dist: list[float] = []
    for i, drv in enumerate(drivers):
        d = drv.disturbance
        for t_s, dt_s, steps, (u1, u2) in drv.segments():
            segf.append((t_s, dt_s, u1, u2))
            segi.append((i, steps, len(dist)))
            h = dt_s / steps
            hh = 0.5 * h
            for k in range(steps):   # where `advance` samples d(t): t_k, t_k + h/2, t_k + h
                tk = t_s + k * h
                dist += (*d(tk), *d(tk + hh), *d(tk + h))
    xs = np.array([drv.x for drv in drivers], dtype=np.float64)
    delta = np.empty((len(drivers), 2))
    # every array is built here, so its type is known: the overload's entry point, without the dispatcher's typing
    _entry(kernel, drivers[0].params)(xs, np.array(segf), np.array(segi, np.int64), np.array(dist),
                                      drivers[0].params, delta)
    return [drv.finish_period(tuple(row), (d1, d2))
            for drv, row, (d1, d2) in zip(drivers, xs.tolist(), delta.tolist(), strict=True)]


