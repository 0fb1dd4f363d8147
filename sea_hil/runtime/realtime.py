"""Real-time levers of a 1 kHz loop (`[timing]`, docs/timing.md), applied by the real-time clock's parts, never by a
node's logic, and never in lockstep (simulated time: nothing here can change a lockstep result).

- `ThreadPolicy(timing).apply()`: in the calling thread: the process's GIL switch interval, SCHED_FIFO (for the
  driver thread, or for every thread of the process) and a CPU pin; `undo()` when the loop ends. What the OS
  refuses (EPERM without CAP_SYS_NICE, a CPU outside the allowed set, no such call on this OS) is logged once and
  skipped: the loop runs on, unprivileged.
- `child_cpus(timing)`: the CPUs the session's child processes are pinned to (every allowed CPU but the driver's).
- `node_priority(timing, role)`: the SCHED_FIFO priority an edge or controller started as a process of its own takes.
- `SlackCollector`: `gc.freeze()` after start-up and automatic collection off while the loop runs; the loop calls
  `tick(remaining_ns)` after its work and a due collection runs only when at least `gc_slack_us` remain to the next
  deadline (postponed at most until 8x the generation-0 threshold has accumulated). `stop()` restores the GC.
"""
from __future__ import annotations

import gc
import logging
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from sea_hil.config.timing import TimingConfig

log = logging.getLogger("sea_hil.runtime")
_POSTPONE_FACTOR = 8   # a due collection waits for slack at most until 8x the gen-0 threshold has accumulated


def _allowed_cpus() -> set[int] | None:
    try:
        return set(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None


def child_cpus(timing: TimingConfig) -> set[int] | None:
    """The CPUs for the session's child processes when the driver is pinned (`driver_cpu`), else None."""
    allowed = _allowed_cpus()
    if timing.driver_cpu < 0 or allowed is None or timing.driver_cpu not in allowed or len(allowed) < 2:
        return None
    return allowed - {timing.driver_cpu}


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


def pin_process(pid: int, cpus: set[int] | None) -> bool:
    """Pin process `pid` to `cpus` (None: nothing); a refusal is logged, never raised. True if pinned."""
    if not cpus:
        return False
    try:
        os.sched_setaffinity(pid, cpus)
        return True
    except (AttributeError, OSError) as err:
        log.info("timing: cannot pin pid %d to CPUs %s (%s); it runs unpinned", pid, sorted(cpus), err)
        return False


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
    """`[timing]`'s switch interval, SCHED_FIFO priority and CPU pin for the calling thread (Linux: pid 0 of
    `sched_setscheduler` / `sched_setaffinity` is the calling thread); with `realtime_scope = "process"` every other
    thread of the process gets SCHED_FIFO one priority lower (so the GIL's holders are not starved by other load
    while the driver waits for them), and threads created later by them inherit it. `undo()` puts every thread it
    raised back to SCHED_OTHER (process scope: also the threads that inherited it meanwhile) and the switch
    interval back."""

    def __init__(self, timing: TimingConfig, role: str = "driver") -> None:
        self.timing, self.role = timing, role
        self._raised: list[int] = []
        self._switch_s: float | None = None

    def apply(self) -> dict[str, object]:
        """Apply in the calling thread; returns what took effect (a refusal is logged once, never raised)."""
        timing, applied = self.timing, {}
        if timing.switch_interval_us > 0:
            self._switch_s = sys.getswitchinterval()
            sys.setswitchinterval(timing.switch_interval_us * 1e-6)
            applied["switch_interval_us"] = timing.switch_interval_us
        if timing.realtime_priority > 0:
            applied.update(self._raise(timing.realtime_priority))
        if timing.driver_cpu >= 0:
            allowed = _allowed_cpus()
            if allowed is not None and timing.driver_cpu in allowed and pin_process(0, {timing.driver_cpu}):
                applied["cpu"] = timing.driver_cpu
            elif allowed is None or timing.driver_cpu not in allowed:
                log.info("timing: CPU %d is not available to the %s thread (allowed: %s); it runs unpinned",
                         timing.driver_cpu, self.role, sorted(allowed) if allowed else "unknown")
        return applied

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
                _fifo(tid, max(1, self.timing.realtime_priority - 1))
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
        if self._switch_s is not None:
            sys.setswitchinterval(self._switch_s)
            self._switch_s = None


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


@dataclass
class SlackCollector:
    """Garbage collection in the loop's slack time (see the module docstring)."""

    slack_ns: int
    collections: int = 0
    postponed: int = 0
    collect_ns: int = 0
    _restore: bool = field(default=False, repr=False)

    @classmethod
    def from_config(cls, timing: TimingConfig) -> SlackCollector | None:
        return cls(timing.gc_slack_us * 1000) if timing.gc_in_slack else None

    def start(self) -> None:
        """After start-up: collect once, move every survivor to the permanent generation, stop automatic GC."""
        gc.collect()
        gc.freeze()
        self._restore = gc.isenabled()
        gc.disable()

    def tick(self, remaining_ns: int) -> None:
        count0, count1, count2 = gc.get_count()
        t0, t1, t2 = gc.get_threshold()
        if count0 < t0:
            return
        if remaining_ns < self.slack_ns and count0 < _POSTPONE_FACTOR * t0:
            self.postponed += 1
            return
        gen = 2 if count2 >= t2 else 1 if count1 >= t1 else 0   # CPython's own choice of generation
        start = time.monotonic_ns()
        gc.collect(gen)
        self.collect_ns += time.monotonic_ns() - start
        self.collections += 1

    def stop(self) -> None:
        """Automatic collection back on (if it was on at `start`); the frozen objects stay frozen (harmless)."""
        if self._restore:
            gc.enable()
            self._restore = False
