"""`advance` calls the compiled overload's entry point directly (no per-call typing of the limb parameters) only for
arguments of exactly the overload's types, and gives the floats the numba dispatcher gives, bit for bit."""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from sea_hil.config.loader import load_config
from sea_hil.jit import loaded
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator import integrator
from sea_hil.plant_emulator.integrator import advance, make_advance_kernel, prepare_advance, substep_times


def _dist(t: float) -> tuple[float, float]:
    return (0.3 * math.sin(12.0 * t), -0.05 * math.cos(7.0 * t))


def _dispatched(t, x, u, dt, n, p):  # type: ignore[no-untyped-def]
    values = [v for ts in substep_times(t, dt, n) for ti in ts for v in _dist(ti)]
    return loaded(make_advance_kernel)(t, x, u, dt, n, p, np.array(values))


def test_entry_point_equals_dispatcher_bit_for_bit() -> None:
    p = limb_params(load_config().plant)
    if not prepare_advance(p):
        pytest.skip("numba not installed: advance runs plain Python")
    rng = random.Random(7)
    x = tuple(rng.uniform(-0.2, 0.2) for _ in range(8))
    integrator._ENTRIES.clear()
    for k in range(300):
        u = (rng.uniform(-8, 8), rng.uniform(-8, 8))
        t, dt, n = k * 1e-3, rng.choice((1e-3, 3.7e-4)), rng.choice((1, 2, 3))
        fast = advance(t, x, u, dt, n, p, _dist)
        assert fast == _dispatched(t, x, u, dt, n, p)
        x = fast
    assert any(key[1] == id(p) for key in integrator._ENTRIES)   # the entry point was taken


def test_other_argument_types_go_through_the_dispatcher() -> None:
    p = limb_params(load_config().plant)
    if not prepare_advance(p):
        pytest.skip("numba not installed: advance runs plain Python")
    x = (0.1, -0.2, 0.0, 0.0, 0.01, 0.02, 0.0, 0.0)
    integrator._ENTRIES.clear()
    as_ints = advance(0.0, x, (0, 1), 1e-3, 2, p, _dist)   # int voltages: not the float overload's types
    assert not any(key[1] == id(p) for key in integrator._ENTRIES)
    assert as_ints == _dispatched(0.0, x, (0, 1), 1e-3, 2, p)
