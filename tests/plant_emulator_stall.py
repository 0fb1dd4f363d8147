"""A deterministic stall of the emulated driver at the clock level, for tests of the tick-miss verdict: every
`every`-th step of the driver (`PlantNode.step_drivers`, inside `RealTimePacer.tick`) takes `stall_s` longer, so the
real-time schedule passes its next deadlines and counts them as misses (docs/timing.md, "What a tick miss is")."""
from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from typing import Any

from sea_hil.plant_emulator.node import PlantNode


@contextlib.contextmanager
def stalled_driver(every: int, stall_s: float) -> Iterator[None]:
    original = PlantNode.step_drivers
    calls = [0]

    def stalled(self: Any) -> Any:
        calls[0] += 1
        if calls[0] % every == 0:
            time.sleep(stall_s)
        return original(self)

    PlantNode.step_drivers = stalled   # type: ignore[method-assign]
    try:
        yield
    finally:
        PlantNode.step_drivers = original   # type: ignore[method-assign]
