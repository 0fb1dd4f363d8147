"""Bounded disturbance torques d1, d2 (Eq. 3), per joint: none, constant, sinusoid, or seeded piecewise-constant
noise. `DisturbanceConfig.per_joint()` gives each joint its kind (the flat keys give both joints the same one)."""
from __future__ import annotations

import math
import random
from collections.abc import Callable

from sea_hil.config.model import DisturbanceConfig, JointDisturbanceConfig

JointTorque = Callable[[float], float]


def _zero(t: float) -> float:
    return 0.0


def joint_disturbance(cfg: JointDisturbanceConfig, joint: int, seed: int) -> JointTorque:
    """d_joint(t) in N m, bounded by |amplitude_nm|; `joint` (0 hip, 1 knee) picks the noise draw."""
    a = cfg.amplitude_nm
    if cfg.kind == "none" or a == 0.0:
        return _zero
    if cfg.kind == "constant":
        return lambda t: a
    if cfg.kind == "sine":
        w = 2.0 * math.pi * cfg.frequency_hz
        return lambda t: a * math.sin(w * t)
    return _HeldNoise(a, cfg.noise_hold_s, seed, joint)


def make_disturbance(cfg: DisturbanceConfig) -> Callable[[float], tuple[float, float]]:
    """Return d(t) -> (d1_nm, d2_nm). Every kind is bounded by |amplitude_nm| per joint."""
    if cfg.is_zero():
        return lambda t: (0.0, 0.0)
    hip, knee = (joint_disturbance(j, i, cfg.seed) for i, j in enumerate(cfg.per_joint()))
    return lambda t: (hip(t), knee(t))


class _HeldNoise:
    """Uniform noise in [-a, a], held for hold_s; the value at t depends only on (seed, floor(t / hold_s), joint):
    draw number `joint` of the stream seeded by the hold index (so both joints with one hold time draw the pair of
    the original two-joint noise)."""

    def __init__(self, a: float, hold_s: float, seed: int, joint: int) -> None:
        self._a = a
        self._hold_s = hold_s
        self._seed = seed
        self._joint = joint
        self._index = -1
        self._value = 0.0

    def __call__(self, t: float) -> float:
        index = int(t // self._hold_s)
        if index != self._index:
            rng = random.Random(self._seed * 1_000_003 + index)
            u = rng.uniform(-1.0, 1.0)
            for _ in range(self._joint):
                u = rng.uniform(-1.0, 1.0)
            self._index = index
            self._value = self._a * u
        return self._value
