"""Fixed-step RK4 with sub-steps; the control input is held (zero-order hold) over a step.

`rk4_core` (in `sea_hil.dynamics`, shared with the controller's nominal model) takes the disturbance torques at t,
t + h/2 and t + h as values, so that it is plain float code which the
offline simulation also compiles with numba (sea_hil/offline/closed_loop.py); `rk4_step` and `advance` sample a disturbance
callable and delegate to it. `advance` (the plant emulator's per-sample integration) runs its sub-steps in a kernel
compiled from the same source with numba (`sea_hil.jit`) once `prepare_advance` has loaded it (a node calls that
before its loop, so no period pays for numba's import or cache load); before that, with `jit=False` or without numba
it runs the same body as plain Python. Both give the same floats bit for bit (no fast-math, same operation order);
they differ only off the model's domain, where plain Python's `math` raises `ValueError` and the kernel gives NaN.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sea_hil.dynamics import State, rk4_core
from sea_hil.jit import compiled, loaded
from sea_hil.mechanics import LimbParams

Disturbance = Callable[[float], tuple[float, float]]


def _no_disturbance(t: float) -> tuple[float, float]:
    return (0.0, 0.0)


def rk4_step(t: float, x: State, u: tuple[float, float], h: float, p: LimbParams,
             dist: Disturbance = _no_disturbance) -> State:
    """One classical RK4 step of length h (seconds)."""
    hh = 0.5 * h
    return rk4_core(t, x, u, h, p, dist(t), dist(t + hh), dist(t + h))


def substep_times(t: float, dt: float, substeps: int) -> list[tuple[float, float, float]]:
    """(t_i, t_i + h/2, t_i + h) of each RK4 sub-step of `advance(t, ..., dt, substeps)`: where it samples d(t)."""
    h = dt / substeps
    hh = 0.5 * h
    return [(t + i * h, t + i * h + hh, t + i * h + h) for i in range(substeps)]


def make_advance_kernel(fingerprint: str = "") -> Callable[..., State]:
    """The sub-step loop of `advance` as a kernel factory (`sea_hil.jit.compiled`); `fingerprint` keys numba's cache.
    `dist_values` holds d(t_i), d(t_i + h/2), d(t_i + h) of every sub-step i, flat (6 floats per sub-step)."""

    def advance_kernel(t, x, u, dt, substeps, p, dist_values):  # type: ignore[no-untyped-def]
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        h = dt / substeps
        for i in range(substeps):
            j = 6 * i
            x = rk4_core(t + i * h, x, u, h, p, (dist_values[j], dist_values[j + 1]),
                         (dist_values[j + 2], dist_values[j + 3]), (dist_values[j + 4], dist_values[j + 5]))
        return x

    return advance_kernel


def prepare_advance(p: LimbParams, jit: bool = True) -> bool:
    """Load (or compile) `advance`'s numba kernel now (~0.5 s from numba's disk cache, seconds when it compiles) and
    switch `advance` to it; False when numba is not installed (or `jit` is False): `advance` stays plain Python."""
    kernel = compiled(make_advance_kernel) if jit else None
    if kernel is not None:
        kernel(0.0, (0.0,) * 8, (0.0, 0.0), 1e-3, 1, p, np.zeros(6))
    return kernel is not None


def advance(t: float, x: State, u: tuple[float, float], dt: float, substeps: int, p: LimbParams,
            dist: Disturbance = _no_disturbance, *, jit: bool = True) -> State:
    """Advance x over dt seconds with `substeps` RK4 steps, input u held (in the prepared kernel when there is one,
    which gets d(t) sampled here exactly where `rk4_step` samples it: d(t_i), d(t_i + h/2), d(t_i + h) per sub-step)."""
    h = dt / substeps
    kernel = loaded(make_advance_kernel) if jit else None
    if kernel is None:
        for i in range(substeps):
            x = rk4_step(t + i * h, x, u, h, p, dist)
        return x
    # an array: one signature for any sub-step count
    dist_values = np.array([v for times in substep_times(t, dt, substeps) for ti in times for v in dist(ti)])
    if type(substeps) is int and len(x) == 8 and all(type(v) is float for v in (t, dt, *x, *u)):
        out: State = _entry(kernel, p)(t, x, u, dt, substeps, p, dist_values)
    else:
        out = kernel(t, x, u, dt, substeps, p, dist_values)
    return out


# (id(kernel), id(params)) -> (kernel, params, entry): a cache
_ENTRIES: dict[tuple[int, int], tuple[Any, LimbParams, Callable[..., Any]]] = {}
_ENTRIES_MAX = 64


def _entry(kernel: Any, p: LimbParams) -> Any:
    """The compiled entry point of `advance`'s kernel for (float, 8 floats, 2 floats, float, int, p's type, float
    array): what the dispatcher calls for these types, without its per-call typing of the 31-field `p` (most of the
    ~20 us a call took). Only for arguments of exactly these types (`advance` checks), so it runs the machine code
    the dispatcher would pick: the same floats bit for bit (tests/test_integrator_entry.py)."""
    return entry_point(kernel, p, _advance_signature)


def _advance_signature(p_type: Any) -> tuple[Any, ...]:
    from numba import types

    f64 = types.float64
    return (f64, types.UniTuple(f64, 8), types.UniTuple(f64, 2), f64, types.int64, p_type, types.Array(f64, 1, "C"))


def entry_point(kernel: Any, p: LimbParams, signature: Callable[[Any], tuple[Any, ...]]) -> Callable[..., Any]:
    """The entry point of `kernel`'s overload for the numba argument types `signature(numba.typeof(p))` (compiled,
    or loaded from numba's cache, when it is not there yet), cached per kernel and parameter object: a hit costs
    one dict lookup."""
    key = (id(kernel), id(p))
    hit = _ENTRIES.get(key)
    if hit is not None and hit[0] is kernel and hit[1] is p:
        return hit[2]
    import numba

    sig = signature(numba.typeof(p))
    if sig not in kernel.overloads:
        kernel.compile(sig)
    if len(_ENTRIES) >= _ENTRIES_MAX:
        _ENTRIES.clear()
    entry: Callable[..., Any] = kernel.overloads[sig].entry_point
    _ENTRIES[key] = (kernel, p, entry)
    return entry
