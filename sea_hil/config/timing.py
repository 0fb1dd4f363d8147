"""Config of the real-time loops of one process (`[timing]`, docs/timing.md). Lockstep sessions ignore it: they are
paced by simulated time, so nothing here changes a lockstep result."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from sea_hil.config.base import _Frozen


class TimingConfig(_Frozen):
    realtime_priority: int = Field(50, ge=0, le=99, description="SCHED_FIFO priority of the driver thread where "
                                                               "permitted (one log line when not); 0 = normal")
    realtime_scope: Literal["driver", "process", "session"] = Field(
        "session", description="SCHED_FIFO for the driver thread only; `process`: also (one priority lower) every "
                              "other thread of its process (edge, Zenoh, taps: the GIL's holders), restored when it "
                              "stops; `session`: also (two lower) the session's controller processes")
    controller_priority: int = Field(0, ge=0, le=99, description="SCHED_FIFO priority of a controller process's "
                                                                 "threads once started; 0 = normal. `sea-hil run` sets "
                                                                 "it in its children's config (realtime_scope session)")
    merge_buses: bool = Field(True, description="`sea-hil run` with several CAN buses: one driver thread, one edge "
                                                "thread and one recorder tap for all buses (one MergedBus each) "
                                                "instead of one of each per bus; false = one of each per bus")
    driver_process: bool | None = Field(None, description="real-time `sea-hil run`: each driver (one per bus, or one "
                                                           "for the merged buses) in a `sea-hil plant` process of "
                                                           "its own, joined to the edge by an `ipc:` bus (a "
                                                           "`virtual:` bus becomes one) or the given SocketCAN / ipc "
                                                           "bus: no GIL shared by driver and edge; lockstep stays in "
                                                           "one process; false = in-process; unset = by profile: "
                                                           "true for cia402 (its edge produces SYNC), false for sea "
                                                           "(docs/timing.md)")
