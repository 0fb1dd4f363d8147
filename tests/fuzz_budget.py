"""How many hypothesis cases the fuzz tests run: `SEA_HIL_FUZZ_SCALE` times the depth the figures of
docs/reliability.md were measured at (1 = that depth; the default 0.3 keeps the default test run short)."""
from __future__ import annotations

import os

DEFAULT_SCALE = 0.3


def cases(full_depth: int) -> int:
    """`full_depth` scaled by SEA_HIL_FUZZ_SCALE (at least 100 cases)."""
    raw = os.environ.get("SEA_HIL_FUZZ_SCALE", "")
    try:
        scale = float(raw) if raw else DEFAULT_SCALE
    except ValueError as err:
        raise ValueError(f"SEA_HIL_FUZZ_SCALE must be a number, got {raw!r}") from err
    if scale <= 0:
        raise ValueError(f"SEA_HIL_FUZZ_SCALE must be > 0, got {raw!r}")
    return max(100, int(full_depth * scale))
