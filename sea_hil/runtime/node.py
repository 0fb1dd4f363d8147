"""The one node base: every node (driver, edge, controller, recorder) is a `Node`.

Template method in the style of python-can's `BusABC`: the base owns the loop, the lifecycle and the stats record;
a subclass implements small hooks:

- `_step() -> bool`: one iteration, blocking at most one poll period; True if it made progress (handled input);
- `finished() -> bool`: the node's work is done (default: never, it runs until stopped);
- `_on_start(duration_s)` / `_on_stop()`: around one `run` (e.g. start a schedule, flush);
- `_close()`: release what the node owns (subscribers, taps); called once by the idempotent `close()`;
- `_stats() -> dict`: the node's flat numeric counters (wrapped in the one stats schema by `stats_record()`).

`run(duration_s)` loops until `stop()`, `finished()`, or (when given) `duration_s` has passed without progress;
`start()` runs it in a daemon thread, `close()` stops it, joins the thread and calls `_close()`. A node is a context
manager (`with PlantNode(...) as plant:`). The node cores stay pure; I/O lives in the hooks.
"""
from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar

from sea_hil.stats import schema as stats_schema


class Node:
    """Base of all nodes (see the module docstring for the hooks)."""

    kind: ClassVar[str] = "node"     # `node` field of the stats record: plant | edge | controller | recorder
    join_timeout_s: ClassVar[float | None] = 10.0   # None: `_on_stop` bounds itself, wait for it

    def __init__(self) -> None:
        self.stop_event = threading.Event()
        self.stats_pub: Any = None      # a publisher (`put(bytes)`) for `publish_stats`, set by the subclass
        self._thread: threading.Thread | None = None
        self._closed = False
        self._loop_exit: list[Callable[[], None]] = []   # run when a `run` ends (`on_loop_exit`)

    # ---- the loop -------------------------------------------------------------------------------------------------
    def run(self, duration_s: float | None = None) -> bool:
        """Run until stopped or finished (True if finished); with `duration_s`, give up (False) once that long has
        passed in a step without progress."""
        deadline = None if duration_s is None else time.monotonic_ns() + int(duration_s * 1e9)
        self._on_start(duration_s)
        try:
            while not self.stop_event.is_set() and not self.finished():
                if not self._step() and deadline is not None and time.monotonic_ns() > deadline:
                    return False
        finally:
            self._on_stop()
            while self._loop_exit:
                self._loop_exit.pop()()
        return self.finished()

    def on_loop_exit(self, fn: Callable[[], None]) -> None:
        """Run `fn` once when the current `run` ends (after `_on_stop`, last registered first): a clock's part
        undoing what it did to the thread or process for the loop (e.g. `SlackCollector.stop`)."""
        self._loop_exit.append(fn)

    def start(self, duration_s: float | None = None) -> threading.Thread:
        """`run` in a daemon thread named after the node."""
        self._thread = threading.Thread(target=self.run, args=(duration_s,), name=self.kind, daemon=True)
        self._thread.start()
        return self._thread

    def stop(self) -> None:
        self.stop_event.set()

    def join(self, timeout_s: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout=self.join_timeout_s if timeout_s is None else timeout_s)

    def close(self) -> None:
        """Stop, join the thread `start` made, release resources. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self.stop()
        self.join()
        self._close()

    def __enter__(self) -> Node:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    # ---- stats ----------------------------------------------------------------------------------------------------
    def stats_dict(self) -> dict[str, Any]:
        """This node's flat numeric counters (the `_stats` hook)."""
        return self._stats()

    def stats_record(self, *, final: bool = False, t_ns: int | None = None) -> dict[str, Any]:
        """This node's counters as one record of the stats schema (`sea_hil.stats.schema`)."""
        return stats_schema.stats_record(self.kind, self._stats(), final=final, t_ns=t_ns)

    def publish_stats(self, final: bool = False) -> None:
        if self.stats_pub is not None:
            self.stats_pub.put(json.dumps(self.stats_record(final=final)).encode())

    # ---- hooks ----------------------------------------------------------------------------------------------------
    def _step(self) -> bool:
        raise NotImplementedError

    def finished(self) -> bool:
        return False

    def _on_start(self, duration_s: float | None) -> None:
        """Before the loop of one `run`."""

    def _on_stop(self) -> None:
        """After the loop of one `run` (also when it raised)."""

    def _close(self) -> None:
        """Release what the node owns (once)."""

    def _stats(self) -> dict[str, Any]:
        return {}
