"""Bounded disturbance torques d1, d2 (Eq. 3), per joint: none, constant, sinusoid, or seeded piecewise-constant
noise. `DisturbanceConfig.per_joint()` gives each joint its kind (the flat keys give both joints the same one)."""
from __future__ import annotations

import math
import random
from collections.abc import Callable

import numpy as np

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


class DisturbanceTable:
    """The disturbance torques a driver integrates with, precomputed for compiled loops: row k * substeps + i holds
    d(t_i), d(t_i + h/2), d(t_i + h) of sub-step i of sample k, sampled in the order and at the float times
    `DriverCore.step` -> `advance` samples them (t = k * period_ns * 1e-9, h = period / substeps), so a stateful
    noise disturbance gives the same values. Grown on demand (`upto`), in sample order."""

    CHUNK = 4096   # samples added at a time

    def __init__(self, cfg: DisturbanceConfig, period_ns: int, substeps: int) -> None:
        self.zero = cfg.is_zero()     # every joint, incl. per-joint tables ([disturbance.hip] / [disturbance.knee])
        self._dist = None if self.zero else make_disturbance(cfg)
        self.period_ns, self.substeps = period_ns, substeps
        self.rows = np.zeros((0, 6))
        self.samples = 0

    def upto(self, n_samples: int) -> np.ndarray:
        """The table covering samples 0 .. n_samples - 1 (at least)."""
        if n_samples > self.samples:
            n = max(n_samples, self.samples + self.CHUNK)
            self.rows = np.concatenate([self.rows, self._rows(self.samples, n)])
            self.samples = n
        return self.rows

    def _rows(self, k0: int, k1: int) -> np.ndarray:
        substeps = self.substeps
        out = np.zeros(((k1 - k0) * substeps, 6))
        if self._dist is None:
            return out
        dist, h = self._dist, (self.period_ns * 1e-9) / substeps
        hh = 0.5 * h
        for k in range(k0, k1):
            t = k * self.period_ns * 1e-9
            for i in range(substeps):
                ti = t + i * h
                out[(k - k0) * substeps + i] = (*dist(ti), *dist(ti + hh), *dist(ti + h))
        return out
