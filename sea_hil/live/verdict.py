"""The live view's running verdict (`/live/verdict`): summary.json's rules (sea_hil/verdict/rules.py `verdict`)
applied to what the live view has seen so far, so a user watching the session sees it turn `degraded` or `invalid`
when it does, and the last message (`final`) says what summary.json will say of the same judged inputs.

What it judges, as summary.json does: the drives' safe-state latches from their heartbeats (`/can/raw`, the shared
rule of sea_hil/drive_latches.py; without a heartbeat, the latches the edges counted in their `/stats`), and the
counters of each edge's and controller's latest `/stats` record (the nodes publish it when they stop: the
counters are judged at the end, the latches as they happen; late, lost and stale setpoints, lost states,
envelope rejections, saturated steps, every rejection class, the cia402 SYNC misses against the host floor the
parent measured), each limb's edge and controller on their own, under the session's `[verdict]` thresholds and
lockstep flag (the parent's `LiveSpec`). A cia402 session's latches come from its statusword TPDOs when the view
follows the bus's CANopen (`LiveView.follow_canopen`). What only summary.json judges: the recording (the recorder's
own losses, its completeness against the nodes' counters) and the driver's tick misses (the recorder's final
metadata). Pure: messages in, verdict out.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sea_hil.config.verdict import VerdictConfig
from sea_hil.drive_latches import LatchLog, edge_latch_entries, in_time_order, latch_entries, latches_of_stats
from sea_hil.protocol.can_frames import Heartbeat
from sea_hil.verdict.edge_blocks import rejections_blocks, split_edge_stats, uplink_losses
from sea_hil.verdict.rules import OK, verdict

# the reasons only summary.json gives: from the recording itself, and the driver's ticks (the recorder's final metadata)
SUMMARY_ONLY = ("recording_losses", "recording_incomplete", "recording_unverified", "tick_misses")
ANCHOR_STATES_KEPT = 4096   # states remembered until one of them has its tracking record (the time-axis anchor)
_LEVEL = {"ok": "INFO", "degraded": "WARNING", "invalid": "ERROR"}


class LiveVerdict:
    """The running verdict (see the module docstring). One owner (not thread-safe)."""

    def __init__(self, cfg: VerdictConfig | None = None, *, lockstep: bool = False,
                 floor: Mapping[str, float] | None = None, limbs: Mapping[int, str] | None = None) -> None:
        """`limbs`: node id -> limb name, in the session's limb order (summary.json's `sea-hil.limbs`), so reasons
        name and order the limbs as summary.json does; an edge not in it is named by its stats key, else node id."""
        self.cfg = cfg or VerdictConfig()
        self.limbs = dict(limbs or {})
        self.lockstep = lockstep
        self.floor = dict(floor) if floor else None
        self.latches = LatchLog()
        self.heartbeats = 0
        self._first_can_ns: int | None = None
        self._last_tracking: tuple[float, int] | None = None   # (largest cycle time t_s, its log time)
        self._sample_ns: dict[int, int] = {}                  # state seq -> sample time, until anchored
        self._anchor_ns: int | None = None                    # sample time of cycle time 0 (edge latches)
        self._edges: dict[int, dict[str, Any]] = {}           # node id -> the edge's latest /stats record
        self._controllers: dict[int | None, dict[str, Any]] = {}   # node id (None: none given) -> latest record
        self.status = OK

    # -- input ---------------------------------------------------------------------------------------------------
    def on_can(self, t_ns: int) -> None:
        """Any CAN frame (the latch times count from the first, as summary.json's `drive_faults`)."""
        if self._first_can_ns is None:
            self._first_can_ns = t_ns

    def on_heartbeat(self, t_ns: int, hb: Heartbeat) -> None:
        self.heartbeats += 1
        self.latches.on_heartbeat(t_ns, hb)

    def on_state(self, payload: Mapping[str, Any]) -> None:
        seq, sample = payload.get("seq"), payload.get("sample_t_ns")
        if self._anchor_ns is None and isinstance(seq, int) and isinstance(sample, int):
            self._sample_ns[seq] = sample
            if len(self._sample_ns) > ANCHOR_STATES_KEPT:
                del self._sample_ns[next(iter(self._sample_ns))]

    def on_tracking(self, t_ns: int, payload: Mapping[str, Any]) -> None:
        t_s = payload.get("t_s")
        if not isinstance(t_s, (int, float)):
            return
        if self._last_tracking is None or t_s > self._last_tracking[0]:
            self._last_tracking = (float(t_s), t_ns)
        seq = payload.get("state_seq")
        if self._anchor_ns is None and seq in self._sample_ns:
            self._anchor_ns = self._sample_ns[seq] - round(t_s * 1e9)
            self._sample_ns.clear()

    def on_stats(self, payload: Mapping[str, Any]) -> None:
        """A node's stats record; one the verdict cannot read (a latch count without its details, a non-numeric
        counter it needs) raises KeyError, TypeError or ValueError here, before it is kept, so every later verdict
        still judges (`LiveView` counts it in `ignored`)."""
        node = payload.get("node", "edge")
        if node == "edge":
            record = dict(payload)
            latches_of_stats(record)   # KeyError / ValueError / TypeError on a malformed latch block
            self._edges[int(record.get("node_id", 1))] = record
        elif node == "controller":
            uplink_losses(dict(payload), {})   # ValueError / TypeError on a non-numeric state_seq_lost
            node_id = payload.get("node_id")
            self._controllers[int(node_id) if node_id is not None else None] = dict(payload)

    # -- the verdict ---------------------------------------------------------------------------------------------
    def _drive_faults(self) -> list[dict[str, Any]]:
        """summary.json's `drive_faults` of what has been seen: from the heartbeats when there were any, else from
        the edges' latest records (never both), `after_session` against the latest measured sample so far."""
        if self.heartbeats:
            end = self._last_tracking[1] if self._last_tracking is not None else None
            t0 = self._first_can_ns or 0
            return in_time_order(latch_entries(self.latches.latches, t0, end, "can"))
        end = None if self._anchor_ns is None or self._last_tracking is None else \
            self._anchor_ns + round(self._last_tracking[0] * 1e9)
        return edge_latch_entries(self._edges.values(), end)

    def summary(self) -> dict[str, Any]:
        """The summary.json blocks the live view can fill (the rest absent: the rules give no reason for them)."""
        order = [n for n in self.limbs if n in self._edges] + sorted(n for n in self._edges if n not in self.limbs)
        edges = [self._edges[n] for n in order]
        first = edges[0] if edges else {}
        det, timing = split_edge_stats(first)
        rejected, rejected_timing = rejections_blocks(first)
        out: dict[str, Any] = {"lockstep": self.lockstep, "drive_faults": self._drive_faults(), "edge": det,
                               "rejections": rejected,
                               "timing": {"edge": timing, "rejections": rejected_timing}}
        if self.floor is not None:
            out["timing"]["driver"] = {"floor": self.floor}
        if len(edges) > 1:
            out["limbs"] = [self._limb_block(e) for e in edges]
        losses = uplink_losses(self._controller_of(first, several=len(edges) > 1 or len(self.limbs) > 1), first)
        if losses is not None:
            out["link_losses"] = losses
        return out

    def _limb_block(self, edge: Mapping[str, Any]) -> dict[str, Any]:
        """A `limbs` entry of several limbs: the limb's edge counters, rejections and link losses (summary.json's)."""
        out = {"limb": self._limb_name(edge), "edge": split_edge_stats(dict(edge))[0],
               "rejections": rejections_blocks(dict(edge))[0]}
        losses = uplink_losses(self._controller_of(edge, several=True), dict(edge))
        if losses is not None:
            out["link_losses"] = losses
        return out

    def _controller_of(self, edge: Mapping[str, Any], *, several: bool) -> dict[str, Any]:
        """The latest record of the edge's limb's controller: of its node id, else one that gives none (an outside
        controller); with one limb, the latest of any ({} before one is seen)."""
        node_id = int(edge.get("node_id", 1))
        if node_id in self._controllers or several:
            return self._controllers.get(node_id, self._controllers.get(None, {}))
        return next(reversed(self._controllers.values()), {})

    def _limb_name(self, stats: Mapping[str, Any]) -> str:
        node_id = int(stats.get("node_id", 1))
        if node_id in self.limbs:
            return self.limbs[node_id]
        key = stats.get("key")   # `<prefix>/<limb>/stats` (a record the recorder took from Zenoh)
        return key.split("/")[-2] if isinstance(key, str) and key.count("/") >= 2 else f"node {node_id}"

    def judge(self) -> dict[str, Any]:
        """summary.json's `verdict` of what has been seen so far."""
        return verdict(self.summary(), self.cfg)

    def message(self, final: bool = False) -> tuple[dict[str, Any], str | None]:
        """(the `/live/verdict` message, the log level of a status change since the last message or None)."""
        v = self.judge()
        reasons = v["reasons"]
        changed = v["status"] != self.status
        self.status = v["status"]
        msg = {"status": v["status"], "codes": [str(r["code"]) for r in reasons],
               "reasons": [str(r["message"]) for r in reasons], "final": final}
        return msg, _LEVEL[v["status"]] if changed else None
