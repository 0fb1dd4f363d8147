"""Every latch of a drive's safe state, from its HEARTBEATs: one rule for the report, which reads the heartbeats back
from a recording's CAN tap (sea_hil/report/drive_faults.py), and the edge, which sees them live and counts them in
its `/stats` record (controller/edge_core.py), so a recording without a CAN tap still says that a drive faulted.

A latch starts at the first heartbeat in FAULT or ESTOP after one that was not (or at the first heartbeat) and ends at
the next heartbeat out of it (cleared) or stays open (still latched at the end); its flags are every error flag the
drive reported during it, its state ESTOP if any heartbeat of it said so. Pure: time and heartbeat in.

In a stats record (flat numbers, sea_hil/stats/schema.py): `drive_latches` (how many), and for the first
`DETAILED` of them `drive_latch_<i>_t_ns`, `_until_t_ns` (the end, or the last heartbeat while still latched),
`_state` (`DriverState` value), `_flags` (`ErrorFlags` bits), `_cleared` (0 / 1), and `_node_id` for a latch of
another node than the record's (a cia402 limb's knee), i from 1; `drive_latch_origin_t_ns`
(the time a latch's `t_s` counts from: the edge's first sample) when there is a latch.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from sea_hil.fault_explain import clear_policy, flag_names
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat

SAFE = (DriverState.FAULT, DriverState.ESTOP)
DETAILED = 8            # latches a stats record details (a flapping watchdog: the count says how many more)
COUNT_KEY, ORIGIN_KEY = "drive_latches", "drive_latch_origin_t_ns"


@dataclass
class Latch:
    node_id: int
    t_ns: int                    # the heartbeat that latched
    state: DriverState
    flags: ErrorFlags
    until_t_ns: int              # the heartbeat that ended it, or the last one seen while latched
    cleared: bool = False


class LatchLog:
    """Latches per drive from its heartbeats (see the module docstring); `latches` in the order they began."""

    def __init__(self) -> None:
        self.latches: list[Latch] = []
        self._open: dict[int, Latch] = {}

    def on_heartbeat(self, t_ns: int, hb: Heartbeat) -> None:
        cur = self._open.get(hb.node_id)
        if hb.state in SAFE:
            if cur is None:
                cur = self._open[hb.node_id] = Latch(hb.node_id, t_ns, hb.state, ErrorFlags(hb.flags), t_ns)
                self.latches.append(cur)
            else:
                cur.flags |= hb.flags
                cur.until_t_ns = t_ns
                if hb.state is DriverState.ESTOP:
                    cur.state = hb.state
        elif cur is not None:
            cur.until_t_ns, cur.cleared = t_ns, True
            del self._open[hb.node_id]


def latch_stats(latches: list[Latch], origin_t_ns: int, node_id: int | None = None) -> dict[str, int]:
    """The stats record fields of `latches` (module docstring); a latch of another node than the record's
    `node_id` (a cia402 limb's knee node) also carries its `_node_id`."""
    out = {COUNT_KEY: len(latches)}
    if latches:
        out[ORIGIN_KEY] = origin_t_ns
    for i, la in enumerate(latches[:DETAILED], 1):
        out.update({f"drive_latch_{i}_t_ns": la.t_ns, f"drive_latch_{i}_until_t_ns": la.until_t_ns,
                    f"drive_latch_{i}_state": int(la.state), f"drive_latch_{i}_flags": int(la.flags),
                    f"drive_latch_{i}_cleared": int(la.cleared)})
        if node_id is not None and la.node_id != node_id:
            out[f"drive_latch_{i}_node_id"] = la.node_id
    return out


def latches_of_stats(stats: dict[str, Any]) -> tuple[list[Latch], int]:
    """(the detailed latches, the origin time) of an edge's stats record (`latch_stats`); node id: the latch's
    `_node_id`, else the record's."""
    node = int(stats.get("node_id", 1))
    out = []
    for i in range(1, min(int(stats.get(COUNT_KEY, 0)), DETAILED) + 1):
        p = f"drive_latch_{i}_"
        out.append(Latch(int(stats.get(p + "node_id", node)), int(stats[p + "t_ns"]), DriverState(int(stats[p + "state"])),
                         ErrorFlags(int(stats[p + "flags"])), int(stats[p + "until_t_ns"]),
                         bool(stats[p + "cleared"])))
    return out, int(stats.get(ORIGIN_KEY, 0))


def latch_entries(latches: Iterable[Latch], t0_ns: int, end_ns: int | None, source: str) -> list[dict[str, Any]]:
    """summary.json's `drive_faults` entries of latches (docs/session.md), the report's and the live view's running
    verdict's: `t_s` since `t0_ns`, `after_session` when it began after `end_ns` (the last measured sample; None: not
    known), `source` "can" (heartbeats) or "edge" (its stats record)."""
    return [{"node_id": la.node_id, "t_s": (la.t_ns - t0_ns) * 1e-9, "state": la.state.name,
             "flags": flag_names(la.flags), "in_fault_s": (la.until_t_ns - la.t_ns) * 1e-9, "cleared": la.cleared,
             "clear_policy": clear_policy(la.state, la.flags), "after_session": end_ns is not None and la.t_ns > end_ns,
             "source": source} for la in latches]


def edge_latch_entries(records: Iterable[dict[str, Any]], end_ns: int | None) -> list[dict[str, Any]]:
    """The latches the edges' stats records detail (`latches_of_stats`), as `latch_entries` from each record's
    origin (`source` "edge"), in time order."""
    out = []
    for stats in records:
        latches, origin_ns = latches_of_stats(stats)
        out += latch_entries(latches, origin_ns, end_ns, "edge")
    return in_time_order(out)


def in_time_order(entries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return sorted(entries, key=lambda e: (e["t_s"], e["node_id"]))
