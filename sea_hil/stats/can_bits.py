"""Bits on the wire of classic CAN frames: the one copy of the formula (bus load in reports and benchmarks, docs)."""
from __future__ import annotations

from sea_hil.errors import MalformedFrame


def can_frame_bits(dlc: int, extended: bool = False, *, worst_case: bool = True) -> int:
    """Bits on the wire of one classic CAN data frame including the 3-bit interframe space (Davis et al. 2007):
    standard ``8n + 47 + stuff``, extended ``8n + 67 + stuff`` with ``n = min(dlc, 8)``; worst-case bit stuffing
    ``stuff = floor((34 + 8n - 1)/4)`` (extended: ``54`` instead of ``34``), 0 when not `worst_case`.
    8-byte frames: 135 (std), 160 (ext) bits. The single copy of this formula (bus load, reports, docs)."""
    if not isinstance(dlc, int) or not 0 <= dlc <= 15:
        raise MalformedFrame(f"classic CAN dlc must be 0..15, got {dlc!r}")
    n = min(dlc, 8)
    fixed, stuffed = (67, 54) if extended else (47, 34)
    return 8 * n + fixed + ((stuffed + 8 * n - 1) // 4 if worst_case else 0)
