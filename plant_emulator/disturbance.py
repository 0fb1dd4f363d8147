"""Bounded disturbance torques d1, d2 (Eq. 3): none, constant, sinusoid, or seeded piecewise-constant noise."""
from __future__ import annotations

import math
import random
from typing import Callable

from sea_hil.config import DisturbanceConfig


def make_disturbance(cfg: DisturbanceConfig) -> Callable[[float], tuple[float, float]]:
    """Return d(t) -> (d1_nm, d2_nm). Every kind is bounded by |amplitude_nm| per joint."""
    a1, a2 = cfg.amplitude_nm
    if cfg.kind == "none" or (a1 == 0.0 and a2 == 0.0):
        return lambda t: (0.0, 0.0)
    if cfg.kind == "constant":
        return lambda t: (a1, a2)
    if cfg.kind == "sine":
        w = 2.0 * math.pi * cfg.frequency_hz
        return lambda t: (a1 * math.sin(w * t), a2 * math.sin(w * t))
    return _HeldNoise(a1, a2, cfg.noise_hold_s, cfg.seed)


class _HeldNoise:
    """Uniform noise in [-a, a], held for hold_s; value at t depends only on (seed, floor(t / hold_s))."""

    def __init__(self, a1: float, a2: float, hold_s: float, seed: int) -> None:
        self._a = (a1, a2)
        self._hold_s = hold_s
        self._seed = seed
        self._index = -1
        self._value = (0.0, 0.0)

    def __call__(self, t: float) -> tuple[float, float]:
        index = int(t // self._hold_s)
        if index != self._index:
            rng = random.Random(self._seed * 1_000_003 + index)
            self._index = index
            self._value = (self._a[0] * rng.uniform(-1.0, 1.0), self._a[1] * rng.uniform(-1.0, 1.0))
        return self._value
