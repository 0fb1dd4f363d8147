"""Config of the real-time loops of one process (`[timing]`, docs/timing.md). Lockstep sessions ignore it: they are
paced by simulated time, so nothing here changes a lockstep result."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from sea_hil.config.base import _Frozen


class TimingConfig(_Frozen):
    spin_us: int = Field(0, ge=0, le=1000, description="driver: the last spin_us before each deadline are polled "
                                                       "(the bus, without sleeping) instead of slept; 0 = sleep")
    gc_in_slack: bool = Field(False, description="gc.freeze() after start-up, automatic collection off while the "
                                                 "driver runs; collections run in the driver's slack time")
    gc_slack_us: int = Field(300, ge=0, description="collect only when at least this much remains to the deadline")
    switch_interval_us: int = Field(0, ge=0, description="sys.setswitchinterval for the process hosting the driver "
                                                         "(how long a thread holds the GIL against a waiter); 0 = "
                                                         "Python's default (5000 us)")
    realtime_priority: int = Field(50, ge=0, le=99, description="SCHED_FIFO priority of the driver thread where "
                                                               "permitted (one log line when not); 0 = normal")
    realtime_scope: Literal["driver", "process", "session"] = Field(
        "session", description="SCHED_FIFO for the driver thread only; `process`: also (one priority lower) every "
                              "other thread of its process (edge, Zenoh, taps: the GIL's holders), restored when it "
                              "stops; `session`: also (two lower) the session's controller processes")
    controller_priority: int = Field(0, ge=0, le=99, description="SCHED_FIFO priority of a controller process's "
                                                                 "threads once started; 0 = normal. `sea-hil run` sets "
                                                                 "it in its children's config (realtime_scope session)")
    driver_cpu: int = Field(-1, ge=-1, description="pin the driver thread to this CPU and the session's child "
                                                   "processes to the others; -1 = no pinning")
    merge_buses: bool = Field(True, description="`sea-hil run` with several CAN buses: one driver thread, one edge "
                                                "thread and one recorder tap for all buses (one MergedBus each) "
                                                "instead of one of each per bus; false = one of each per bus")
