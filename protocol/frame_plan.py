"""Precompiled frame plans: one DBC message's signal layout turned once into shifts, masks and scales, so the hot
frames (feedback, voltage commands, heartbeats) are packed and unpacked with a few integer operations instead of a
cantools encode/decode per frame (issue 17: ~50 us per limb-sample through cantools).

A plan is built from the cantools message (`FramePlan.of(message)`), never written by hand; `tests/test_frame_plan.py`
checks it byte for byte against cantools' strict `Message.encode` and its `decode` over random in-range values, the
range boundaries and their tolerance edges, and that a plan rejects exactly the values cantools strict rejects.
Semantics copied from cantools 45 (`conversion.py`, `Message._assert_signal_values_valid`):
- physical -> raw: `round((v - offset) / scale)` (`round` is half-to-even, as Python's); scale 1 / offset 0: `round(v)`;
- strict range: reject `v < minimum - |scale| * 1e-6` or `v > maximum + |scale| * 1e-6` (NaN passes this test in
  cantools and then fails in `round`; a plan raises for it too, as for inf);
- raw -> physical: `raw * scale + offset` (an int for scale 1 / offset 0), two's complement for signed signals.
Only little-endian integer signals without multiplexing are planned (what sea.dbc uses); anything else is a
`ConfigError` when the plan is built. Values go in and come out as tuples in the message's signal order (`names`).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.protocol.frame_codegen import generate


def _unset(*_: Any) -> Any:
    raise RuntimeError("frame plan built without FramePlan.of")


@dataclass(frozen=True)
class SignalPlan:
    name: str
    start: int
    length: int
    signed: bool
    scale: float
    offset: float
    identity: bool         # scale 1, offset 0: raw == physical (an int)
    lo: float              # strict bounds, tolerance included (cantools: |scale| * 1e-6)
    hi: float
    minimum: float         # the DBC range
    maximum: float
    choices: frozenset[int]  # raw values of the value table: cantools strict skips the range test for them

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1


@dataclass(frozen=True)
class FramePlan:
    name: str
    length: int                              # data bytes
    names: tuple[str, ...]
    signals: tuple[SignalPlan, ...]
    used_mask: int                           # bits any signal occupies (the others are reserved, zero)
    # generated straight-line code (sea_hil.protocol.frame_codegen): the hot paths
    pack_plain: Callable[[Sequence[Any]], bytes | None] = field(default=_unset, compare=False, repr=False)
    unpack: Callable[[bytes], tuple[Any, ...]] = field(default=_unset, compare=False, repr=False)
    unpack_plain: Callable[[bytes], tuple[Any, ...] | None] = field(default=_unset, compare=False, repr=False)

    @classmethod
    def of(cls, message: Any) -> FramePlan:
        if message.is_multiplexed() or getattr(message, "is_container", False):
            raise ConfigError(f"frame plan: {message.name} is multiplexed or a container")
        sigs, used = [], 0
        for s in message.signals:
            conv = s.conversion
            if s.byte_order != "little_endian" or conv.is_float or s.minimum is None or s.maximum is None:
                raise ConfigError(f"frame plan: {message.name}.{s.name} must be a little-endian integer signal "
                                  f"with minimum and maximum")
            inner = getattr(conv, "_conversion", conv)    # a value table wraps its linear conversion
            kind = type(inner).__name__
            if kind not in ("IdentityConversion", "LinearConversion"):
                raise ConfigError(f"frame plan: {message.name}.{s.name}: conversion {kind} is not planned")
            tol = abs(conv.scale) * 1e-6
            sp = SignalPlan(s.name, s.start, s.length, s.is_signed, conv.scale, conv.offset,
                            kind == "IdentityConversion", s.minimum - tol, s.maximum + tol, s.minimum, s.maximum,
                            frozenset(int(k) for k in conv.choices) if conv.choices else frozenset())
            for edge in (s.minimum, s.maximum):    # every in-range value must fit the field (bitstruct would raise)
                raw = _raw(sp, edge)
                if not (-(1 << (sp.length - 1)) <= raw < (1 << (sp.length - 1)) if sp.signed
                        else 0 <= raw <= sp.mask):
                    raise ConfigError(f"frame plan: {message.name}.{s.name}: range does not fit {s.length} bits")
            sigs.append(sp)
            used |= sp.mask << sp.start
        plan = cls(message.name, message.length, tuple(s.name for s in sigs), tuple(sigs), used)
        pack_plain, unpack, unpack_plain = generate(plan)
        return dataclasses.replace(plan, pack_plain=pack_plain, unpack=unpack, unpack_plain=unpack_plain)

    # ---- encode ------------------------------------------------------------------------------------------------
    def encode(self, values: Sequence[Any]) -> bytes:
        """The frame's data bytes for physical `values` (signal order); `MalformedFrame` for a value cantools strict
        refuses (out of range with its tolerance, NaN, inf, not a number)."""
        word = 0
        for s, v in zip(self.signals, values, strict=True):
            t = type(v)
            if t is not float and t is not int and not isinstance(v, (int, float)):   # as cantools: subclasses too
                raise MalformedFrame(f"{self.name}.{s.name}: {v!r} is not a number")
            if not s.lo <= v <= s.hi and not _in_table(s, v):      # the range test is False for NaN
                raise MalformedFrame(f"{self.name}.{s.name}: {v!r} outside [{s.lo}, {s.hi}] (strict DBC range)")
            raw = round(v) if s.identity else round((v - s.offset) / s.scale)
            word |= (raw & s.mask) << s.start
        return word.to_bytes(self.length, "little")

    # ---- decode ------------------------------------------------------------------------------------------------
    def decode(self, data: bytes) -> tuple[Any, ...]:
        """Physical values (signal order) of `data`, as cantools `decode(decode_choices=False)` gives them;
        `MalformedFrame` for a wrong length or reserved bits set. Range and enum checks are the caller's
        (`unpack_plain` does them for the common case)."""
        if len(data) != self.length:
            raise MalformedFrame(f"{self.name}: {len(data)} data bytes, expected {self.length}")
        word = int.from_bytes(data, "little")
        if word & ~self.used_mask:
            raise MalformedFrame(f"{self.name}: reserved bits set in {bytes(data).hex()}")
        return self.unpack(data)


def _in_table(s: SignalPlan, v: float) -> bool:
    """A finite value whose raw value is in the signal's value table (cantools strict skips its range test)."""
    return bool(s.choices) and math.isfinite(v) and _raw(s, v) in s.choices


def _raw(s: SignalPlan, v: float) -> int:
    return round(v) if s.identity else round((v - s.offset) / s.scale)
