"""The summary blocks of an edge's `/stats` record (and the controller's), as summary.json has them and the verdict
judges them: `split_edge_stats` (`edge`: the deterministic counters; `timing.edge`: the wall-time-derived ones),
`rejections_blocks` (`rejections`, `timing.rejections`: every rejection class) and `uplink_losses` (`link_losses`).
One mapping for the edge's final record (sea_hil/report/session_summary.py) and its latest one (the live view's
running verdict, sea_hil/live/verdict.py). Pure: records in, blocks out.
"""
from __future__ import annotations

from typing import Any

from sea_hil.protocol.payload_fields import RejectReason

# edge /stats keys derived from wall-clock time: loop and apply times, overruns of the real-time period, lockstep
# re-sends after a 100 ms wait timed out and the repeated answers they draw (duplicate setpoints, dropped as stale),
# extra commands on real-time setpoint arrival, the cia402 SYNC producer's missed periods (`latency_*` go to
# timing.latency_us)
EDGE_TIMING_PREFIXES = ("latency_", "apply_latency_us_", "loop_us_", "can_")   # can_: the bus-timing model
EDGE_TIMING_KEYS = frozenset({"loop_overruns", "lockstep_resends", "lockstep_startup_resends", "arrival_commands",
                              "seq_duplicates", "stale_setpoints", "cia402_sync_misses"})


# every class of input the edge rejects (counted, logged, dropped), by its /stats counter: `rejections` in
# summary.json; the wall-time-derived one (lockstep re-sends draw duplicate answers) under `timing.rejections`
REJECTION_CLASSES = (*(f"payload_rejected_{r.value}" for r in RejectReason), "unexpected_payloads", "epoch_old",
                     "epoch_foreign", "setpoints_out_of_envelope", "late_setpoints", "late_samples",
                     "rejected_frames", "rejected_samples", "edge_fallback_rejected")
TIMING_REJECTION_CLASSES = ("stale_setpoints",)


def rejections_blocks(edge: dict[str, Any]) -> tuple[dict[str, int], dict[str, int]]:
    """(`rejections`, `timing.rejections`): the count of every rejection class in the edge's final /stats record (0
    where the recording has none of it: an older recording, the paper's placement without the edge's fallback)."""
    def block(classes: tuple[str, ...]) -> dict[str, int]:
        return {k: int(edge.get(k, 0)) for k in classes}
    return block(REJECTION_CLASSES), block(TIMING_REJECTION_CLASSES)


def split_edge_stats(edge: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The edge's final /stats record -> (deterministic counters, wall-time-derived ones without `latency_*`)."""
    det: dict[str, Any] = {}
    timing: dict[str, Any] = {}
    for k in sorted(edge):
        if k in ("key", "final", "node", "t_ns", "lockstep"):   # the stats record's envelope (t_ns: the writer's clock)
            continue
        if k in EDGE_TIMING_KEYS or k.startswith(EDGE_TIMING_PREFIXES):
            if not k.startswith("latency_"):
                timing[k] = edge[k]
        else:
            det[k] = edge[k]
    return det, timing


def uplink_losses(controller: dict[str, Any], edge: dict[str, Any]) -> dict[str, int] | None:
    """`link_losses`: states missing on arrival at the controller beyond the uplink model's own drops (the
    controller's stream-seq gaps `state_seq_lost`, less the states a newer one replaced before it read them,
    `states_superseded`: real time, they arrived; less the edge's `uplink_dropped`); None without the controller's
    counter."""
    if "state_seq_lost" not in controller:
        return None
    lost = int(controller["state_seq_lost"]) - int(controller.get("states_superseded", 0))
    return {"uplink_beyond_model": max(0, lost - int(edge.get("uplink_dropped", 0)))}
