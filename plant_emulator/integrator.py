"""Fixed-step RK4 with sub-steps; the control input is held (zero-order hold) over a step."""
from __future__ import annotations

from typing import Callable

from plant_emulator.dynamics import State, f
from protocol.mechanics import LimbParams

Disturbance = Callable[[float], tuple[float, float]]


def _no_disturbance(t: float) -> tuple[float, float]:
    return (0.0, 0.0)


def rk4_step(t: float, x: State, u: tuple[float, float], h: float, p: LimbParams,
             dist: Disturbance = _no_disturbance) -> State:
    """One classical RK4 step of length h (seconds)."""
    hh = 0.5 * h
    k1 = f(t, x, u, p, dist(t))
    x2 = tuple(a + hh * b for a, b in zip(x, k1))
    dm = dist(t + hh)
    k2 = f(t + hh, x2, u, p, dm)
    x3 = tuple(a + hh * b for a, b in zip(x, k2))
    k3 = f(t + hh, x3, u, p, dm)
    x4 = tuple(a + h * b for a, b in zip(x, k3))
    k4 = f(t + h, x4, u, p, dist(t + h))
    h6 = h / 6.0
    return tuple(a + h6 * (b + 2.0 * c + 2.0 * d + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4))  # type: ignore


def advance(t: float, x: State, u: tuple[float, float], dt: float, substeps: int, p: LimbParams,
            dist: Disturbance = _no_disturbance) -> State:
    """Advance x over dt seconds with `substeps` RK4 steps, input u held."""
    h = dt / substeps
    for i in range(substeps):
        x = rk4_step(t + i * h, x, u, h, p, dist)
    return x
