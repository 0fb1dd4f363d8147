"""CLI shorthands for robustness scenarios: `--disturbance` and `--mismatch` to config overrides.

--disturbance: comma-separated `[JOINT=]KIND[:AMPLITUDE[@RATE]]`, JOINT hip or knee (no joint: both joints),
    KIND constant | sine | noise | none, AMPLITUDE in N m (`0.05`, `0.05Nm`), RATE the sine frequency (`2Hz`) or
    the noise hold time (`10ms`, `0.01s`). E.g. `knee=sine:0.05Nm@2Hz,hip=constant:0.5Nm`, `noise:0.05Nm@10ms`.
    Each joint becomes a [disturbance.hip] / [disturbance.knee] table.
--mismatch: comma-separated `NAME=+P%` (or `-P%`): the controller's nominal model ([controller.model]) is the plant's
    value times (1 + P/100). NAME is a group (mass, inertia, stiffness, damping, all = mass+inertia+stiffness) or
    one parameter (m1, m2, i1, i2, k1, k2, b1, b2). E.g. `mass=+20%,stiffness=-20%`.
"""
from __future__ import annotations

import re
from typing import Any

from sea_hil.config.loader import load_config
from sea_hil.config.model import PlantConfig
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError

JOINTS = ("hip", "knee")
KINDS = ("constant", "sine", "noise", "none")
PARAMS = {"m1": "m1_kg", "m2": "m2_kg", "i1": "i1_kgm2", "i2": "i2_kgm2", "k1": "k1_n_per_m", "k2": "k2_n_per_m",
          "b1": "b1_nms", "b2": "b2_nms"}
GROUPS = {"mass": ("m1", "m2"), "inertia": ("i1", "i2"), "stiffness": ("k1", "k2"), "damping": ("b1", "b2"),
          "all": ("m1", "m2", "i1", "i2", "k1", "k2")}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_AMPLITUDE = re.compile(rf"^({_NUMBER})\s*(?:N\s*m|Nm|N·m)?$", re.IGNORECASE)
_RATE = re.compile(rf"^({_NUMBER})\s*(hz|ms|s)$", re.IGNORECASE)
_PERCENT = re.compile(rf"^({_NUMBER})\s*%$")


def _joint_spec(text: str, spec: str) -> dict[str, Any]:
    kind, _, rest = text.partition(":")
    kind = kind.strip().lower()
    if kind not in KINDS:
        raise ConfigError(f"--disturbance {spec!r}: kind {kind!r} is not one of {', '.join(KINDS)}")
    out: dict[str, Any] = {"kind": kind}
    if kind == "none":
        return out
    amp_text, _, rate_text = rest.partition("@")
    m = _AMPLITUDE.match(amp_text.strip())
    if not m:
        raise ConfigError(f"--disturbance {spec!r}: amplitude {amp_text!r} is not a number of N m (e.g. 0.05Nm)")
    out["amplitude_nm"] = float(m.group(1))
    if rate_text:
        r = _RATE.match(rate_text.strip())
        if not r:
            raise ConfigError(f"--disturbance {spec!r}: {rate_text!r} is not a frequency (2Hz) or hold time (10ms)")
        value, unit = float(r.group(1)), r.group(2).lower()
        if kind == "sine" and unit == "hz":
            out["frequency_hz"] = value
        elif kind == "noise" and unit in ("ms", "s"):
            out["noise_hold_s"] = value * (1e-3 if unit == "ms" else 1.0)
        else:
            raise ConfigError(f"--disturbance {spec!r}: '@{rate_text}' needs Hz for sine, ms or s for noise "
                              f"(and nothing for {kind})" if kind != "constant" else
                              f"--disturbance {spec!r}: a constant takes no '@' rate")
    elif kind == "sine":
        raise ConfigError(f"--disturbance {spec!r}: a sine needs its frequency, e.g. sine:0.05Nm@2Hz")
    return out


def disturbance_overrides(spec: str) -> dict[str, Any]:
    """`--disturbance SPEC` as {"hip": {...}, "knee": {...}} overrides of [disturbance]."""
    out: dict[str, Any] = {}
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            raise ConfigError(f"--disturbance {spec!r}: empty item")
        joint, sep, text = part.partition("=")
        joints = (joint.strip().lower(),) if sep else JOINTS
        if not sep:
            text = part
        for j in joints:
            if j not in JOINTS:
                raise ConfigError(f"--disturbance {spec!r}: joint {j!r} is not hip or knee")
            if j in out:
                raise ConfigError(f"--disturbance {spec!r}: {j} given twice")
            out[j] = _joint_spec(text, spec)
    return out


def mismatch_factors(spec: str) -> dict[str, float]:
    """`--mismatch SPEC` as {PlantConfig field: factor}, e.g. {"m1_kg": 1.2, "m2_kg": 1.2}."""
    out: dict[str, float] = {}
    for part in (p.strip() for p in spec.split(",")):
        name, sep, value = part.partition("=")
        name = name.strip().lower()
        m = _PERCENT.match(value.strip())
        if not sep or not m:
            raise ConfigError(f"--mismatch {spec!r}: {part!r} is not NAME=+P% (e.g. mass=+20%)")
        factor = 1.0 + float(m.group(1)) / 100.0
        if factor <= 0.0:
            raise ConfigError(f"--mismatch {spec!r}: {part!r} leaves a parameter <= 0")
        names = GROUPS.get(name, (name,) if name in PARAMS else None)
        if names is None:
            raise ConfigError(f"--mismatch {spec!r}: {name!r} is not one of "
                              f"{', '.join([*GROUPS, *PARAMS])}")
        for n in names:
            if PARAMS[n] in out:
                raise ConfigError(f"--mismatch {spec!r}: {n} given twice")
            out[PARAMS[n]] = factor
    return out


def mismatch_overrides(factors: dict[str, float], plant: PlantConfig) -> dict[str, float]:
    """[controller.model] values: the plant's parameter times its factor."""
    return {field: getattr(plant, field) * f for field, f in factors.items()}


def scenario_config(path: str | None, overrides: dict[str, Any], disturbance: str | None = None,
                    mismatch: str | None = None) -> SeaHilConfig:
    """load_config(path, overrides) with the --disturbance and --mismatch shorthands applied on top (the mismatch
    is relative to the loaded [plant], so it is resolved after a first load)."""
    ov = dict(overrides)
    if disturbance:
        ov["disturbance"] = {**ov.get("disturbance", {}), **disturbance_overrides(disturbance)}
    cfg = load_config(path, ov)
    if not mismatch:
        return cfg
    ctrl = ov.get("controller", {})
    model = {**ctrl.get("model", {}), **mismatch_overrides(mismatch_factors(mismatch), cfg.plant)}
    return load_config(path, {**ov, "controller": {**ctrl, "model": model}})
