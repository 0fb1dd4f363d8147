"""Real-time levers of a 1 kHz loop (`[timing]`, docs/timing.md), applied by the real-time clock's parts, never by a
node's logic, and never in lockstep (simulated time: nothing here can change a lockstep result).

- `ThreadPolicy(timing).apply()`: in the calling thread: SCHED_FIFO (for the driver thread, or for every thread of
  the process); `undo()` when the loop ends. What the OS refuses (EPERM without CAP_SYS_NICE, no such call on this
  OS) is logged once and skipped: the loop runs on, unprivileged.
- `node_priority(timing, role)`: the SCHED_FIFO priority an edge or controller started as a process of its own takes.

The other levers once here (a busy-wait tail, GC in the slack time, the GIL switch interval, CPU pinning) were
measured as no gain once the session runs at SCHED_FIFO and removed (docs/timing.md).
"""
from __future__ import annotations

import logging
import os
import threading
from typing import Any

from sea_hil.config.timing import TimingConfig

log = logging.getLogger("sea_hil.runtime")


def child_priority(timing: TimingConfig) -> int | None:
    """The SCHED_FIFO priority of the session's controller processes (`realtime_scope = "session"`), else None."""
    if timing.realtime_priority <= 0 or timing.realtime_scope != "session":
        return None
    return max(1, timing.realtime_priority - 2)


def node_priority(timing: TimingConfig, role: str) -> int | None:
    """The SCHED_FIFO priority of a node process started on its own (`sea-hil edge | controller`: the compose
    topology, one process per node) with `realtime_scope = "session"`: the edge one below the driver (as its thread in
    `sea-hil run`'s process), the controller two below (`child_priority`); None: not raised."""
    if timing.realtime_priority <= 0 or timing.realtime_scope != "session":
        return None
    return max(1, timing.realtime_priority - (1 if role == "edge" else 2))


def _fifo(tid: int, priority: int) -> None:
    os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))


def _is_fifo(tid: int) -> bool:
    try:
        return os.sched_getscheduler(tid) == os.SCHED_FIFO
    except OSError:
        return False


def _other_threads() -> list[int]:
    """The other threads of this process (Linux /proc/self/task; elsewhere none)."""
    try:
        own = threading.get_native_id()
        return [int(t) for t in os.listdir("/proc/self/task") if int(t) != own]
    except OSError:
        return []


class ThreadPolicy:
    """`[timing]`'s SCHED_FIFO priority for the calling thread (Linux: pid 0 of `sched_setscheduler` is the calling
    thread); with `realtime_scope = "process"` every other
    thread of the process gets SCHED_FIFO one priority lower (so the GIL's holders are not starved by other load
    while the driver waits for them), and threads created later by them inherit it. `undo()` puts every thread it
    raised back to SCHED_OTHER (process scope: also the threads that inherited it meanwhile)."""

    def __init__(self, timing: TimingConfig, role: str = "driver", others_below: int = 1) -> None:
        self.timing, self.role, self.others_below = timing, role, others_below
        self._raised: list[int] = []

    def apply(self) -> dict[str, object]:
        """Apply in the calling thread; returns what took effect (a refusal is logged once, never raised)."""
        if self.timing.realtime_priority > 0:
            return self._raise(self.timing.realtime_priority)
        return {}

    def _raise(self, priority: int) -> dict[str, object]:
        try:
            _fifo(0, priority)
        except (AttributeError, OSError) as err:
            log.warning("timing: SCHED_FIFO %d for the %s thread not permitted (%s); it runs at normal priority "
                        "(docs/timing.md)", priority, self.role, err)
            return {}
        self._raised.append(0)
        self.refresh()
        return {"sched_fifo": priority, "fifo_threads": len(self._raised)}

    def refresh(self) -> None:
        """Process scope, once SCHED_FIFO took effect: raise the threads started since (e.g. an edge thread started
        after the driver's); the loop calls this now and then (a scan of /proc/self/task, ~tens of us)."""
        if self.timing.realtime_scope == "driver" or not self._raised:
            return
        for tid in _other_threads():
            if tid in self._raised:
                continue
            try:
                _fifo(tid, max(1, self.timing.realtime_priority - self.others_below))
                self._raised.append(tid)
            except OSError:   # a thread that has just ended, or a refusal: it keeps its policy
                pass

    def undo(self) -> None:
        if self.timing.realtime_scope != "driver" and self._raised:   # threads started meanwhile inherited it
            self._raised += [t for t in _other_threads() if t not in self._raised and _is_fifo(t)]
        for tid in self._raised:
            try:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            except OSError:   # ended meanwhile
                pass
        self._raised = []


def host_policy(timing: TimingConfig) -> ThreadPolicy | None:
    """`sea-hil run` whose drivers run in processes of their own (`[timing] driver_process`), in its main thread:
    every thread of this process (edge, Zenoh, recorder taps) at SCHED_FIFO one below the driver, as the driver's
    `process` / `session` scope gives them when it runs in this process; its `refresh()` raises threads started
    since, `undo()` restores. None (nothing raised) with `driver` scope or priority 0, or when refused (logged)."""
    if timing.realtime_priority <= 0 or timing.realtime_scope == "driver":
        return None
    policy = ThreadPolicy(TimingConfig(realtime_priority=max(1, timing.realtime_priority - 1),
                                       realtime_scope="process"), "session", others_below=0)
    return policy if policy.apply() else None


def raise_node_process(node: Any, timing: TimingConfig, role: str) -> dict[str, object]:
    """A node process of its own (`node_priority`), in the thread that runs its loop, after its start-up: SCHED_FIFO
    for that thread and (one lower) the process's other threads (Zenoh's), undone when the loop ends; what took
    effect (a refusal is logged once, never raised)."""
    priority = node_priority(timing, role)
    if priority is None:
        return {}
    policy = ThreadPolicy(TimingConfig(realtime_priority=priority, realtime_scope="process"), role)
    applied = policy.apply()
    node.on_loop_exit(policy.undo)
    return applied

