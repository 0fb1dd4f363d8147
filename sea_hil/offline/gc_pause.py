"""`gc_paused()`: no cyclic garbage collection inside the block. Building a session's messages and summary allocates
thousands of small containers; each 700 of them trigger a collection that walks the young generations (and, every
so often, the whole heap: in a Dask worker that heap is large), which cost about a third of an offline sweep point.
The objects a point makes are freed by reference counting; anything cyclic is collected after the block."""
from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
