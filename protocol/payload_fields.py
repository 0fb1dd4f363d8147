"""Field validation shared by the Zenoh payloads and the sequence tracking: integer ranges, finite float pairs, and
the `PayloadRejected` error with its machine-readable reason (for counters)."""
from __future__ import annotations

import math
from enum import StrEnum
from math import isfinite

from sea_hil.errors import MalformedPayload

U32_MAX = 0xFFFF_FFFF
U64_MAX = 0xFFFF_FFFF_FFFF_FFFF


class RejectReason(StrEnum):
    LENGTH = "length"
    MAGIC = "magic"
    VERSION = "version"
    TYPE = "type"
    NONFINITE = "nonfinite"
    ENUM = "enum"
    RANGE = "range"
    KEY = "key"             # well formed, but a type its key does not carry (protocol/keys.py, KEY_PAYLOADS)


class PayloadRejected(MalformedPayload):
    """A `MalformedPayload` carrying a machine-readable `reason` (for counters)."""

    def __init__(self, reason: RejectReason, detail: str) -> None:
        super().__init__(f"malformed payload ({reason.value}): {detail}")
        self.reason = reason


def uint_field(name: str, v: int, hi: int) -> int:
    """`v` if it is an int (not a bool) in [0, hi], else PayloadRejected(RANGE)."""
    if type(v) is int and 0 <= v <= hi:   # the common case first: one type check, no isinstance chain
        return v
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= hi:
        raise PayloadRejected(RejectReason.RANGE, f"{name}={v!r} is not an integer in [0, {hi}]")
    return v


def pair_field(name: str, v: object) -> tuple[float, float]:
    """`v` as a pair of finite floats, else PayloadRejected(RANGE or NONFINITE). A tuple of two finite floats is
    returned as it is (the decoder's and most senders' case: no copy, no generator)."""
    if type(v) is tuple and len(v) == 2 and type(v[0]) is float and type(v[1]) is float:
        if isfinite(v[0]) and isfinite(v[1]):
            return v
        raise PayloadRejected(RejectReason.NONFINITE, f"{name}={v!r} is not finite")
    try:
        a, b = (float(x) for x in v)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as err:
        raise PayloadRejected(RejectReason.RANGE, f"{name}={v!r} is not a pair of floats") from err
    if not (math.isfinite(a) and math.isfinite(b)):
        raise PayloadRejected(RejectReason.NONFINITE, f"{name}={(a, b)!r} is not finite")
    return (a, b)
