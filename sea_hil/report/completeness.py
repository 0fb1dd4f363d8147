"""Is a recording complete? Each recorded channel against the counters the nodes published themselves (issue 32).

The edge's and the controller's final `/stats` records say how much they sent: states published (`uplink_msgs` less
the `uplink_pending` an emulated link still held at the end),
downlink messages sent (`setpoints_sent`, setpoints and voltages share one sequence), VOLTAGE_CMD frames sent
(`commands_sent` + `arrival_commands`); the recorder's own final record (`sea-hil.final` metadata) says how many CAN
frames it saw go missing (`can_frames_missed`, from the frames' rolling sequence numbers) and how many records its
writer dropped. `completeness_block` compares them with what the file holds, channel by channel:

- `complete`: every channel's count equals its node's counter;
- `incomplete`: fewer recorded than sent (a recorder started late, cut off, or a lossy path): `missing` says how many;
- `unverified`: the node's final record is not in the file (its node never finished, or the recorder stopped first,
  or never received that node: a recorder that was not routed the controller's keys), so nothing can be compared;
  (given the node's own `--json` summary from its host, `sea-hil report --node-summary`, the check runs against it);
- `not recorded`: the recording has no CAN tap (`sea-hil record` without `--can`): a deployment choice, not a loss.

`incomplete` lists the channels with a measured shortfall and `unverified` those that could not be checked, the
fields a verdict reads; `complete` is true only when both are empty. Every count is deterministic in lockstep.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sea_hil.recorder.reader import RecordedMessage, SessionData, read_session
from sea_hil.report.limbs import limb_view, recorded_limbs

COMPLETE, INCOMPLETE, UNVERIFIED, NOT_RECORDED = "complete", "incomplete", "unverified", "not recorded"
STATUSES = (COMPLETE, INCOMPLETE, UNVERIFIED, NOT_RECORDED)
NODES = ("edge", "controller")    # the nodes whose final /stats records the check needs

_COUNT = {"type": "integer", "minimum": 0}
_MAYBE_COUNT = {"type": ["integer", "null"], "minimum": 0}
CHANNEL_SCHEMA: dict[str, Any] = {
    "type": "object", "additionalProperties": False,
    "required": ["status", "expected", "recorded", "missing", "source"],
    "properties": {"status": {"enum": list(STATUSES)}, "expected": _MAYBE_COUNT, "recorded": _COUNT,
                   "missing": _MAYBE_COUNT, "extra": _COUNT, "source": {"type": "string"}}}
COMPLETENESS_SCHEMA: dict[str, Any] = {
    "type": "object", "additionalProperties": False,
    "required": ["complete", "incomplete", "unverified", "channels", "final_records", "never_seen",
                 "can_frames_lost", "recorder_dropped"],
    "properties": {
        "complete": {"type": "boolean"},
        "incomplete": {"type": "array", "items": {"type": "string"}},
        "unverified": {"type": "array", "items": {"type": "string"}},
        "channels": {"type": "object", "additionalProperties": CHANNEL_SCHEMA},
        "final_records": {"type": "object", "additionalProperties": _COUNT},
        "never_seen": {"type": "array", "items": {"type": "string"}},
        "can_frames_lost": _MAYBE_COUNT,
        "recorder_dropped": _COUNT,
        "counters_from_node_summaries": {"type": "array", "items": {"type": "string"}},
    }}


COUNTED = ("/zenoh/state", "/zenoh/setpoint", "/zenoh/voltage", "/can/command", "/stats")   # what the check reads


def read_for_completeness(path: Any) -> SessionData:
    """The recording with only what `completeness_block` reads (`COUNTED`, and one `/can/raw` message to tell a CAN
    tap): a pass in constant memory but for those topics (the recorder's result at its end; CAN feedback and raw
    frames are most of a file)."""
    kept: dict[str, list[RecordedMessage]] = {}

    def keep(topic: str, msg: RecordedMessage) -> None:
        if topic in COUNTED or (topic == "/can/raw" and not kept.get(topic)):
            kept.setdefault(topic, []).append(msg)
    data = read_session(path, on_message=keep)
    data.messages.update(kept)
    return data


def _unique_count(data: SessionData, topic: str) -> int:
    return len({(m.payload.get("key"), m.payload.get("seq")) for m in data.messages.get(topic, [])})


def final_records(data: SessionData) -> dict[str, list[dict[str, Any]]]:
    """node kind -> its final /stats records in the file (one per limb's edge/controller)."""
    out: dict[str, list[dict[str, Any]]] = {}
    for m in data.messages.get("/stats", []):
        if m.payload.get("final"):
            out.setdefault(str(m.payload.get("node", "edge")), []).append(m.payload)
    return out


def _channel(recorded: int, finals: list[dict[str, Any]], keys: tuple[str, ...], source: str,
             minus: tuple[str, ...] = ()) -> dict[str, Any]:
    """One channel: `recorded` against the sum of `keys` less `minus` over the node's final records (None: none
    recorded)."""
    if not finals:
        return {"status": UNVERIFIED, "expected": None, "recorded": recorded, "missing": None, "source": source}
    expected = int(sum(int(f.get(k, 0)) for f in finals for k in keys)
                   - sum(int(f.get(k, 0)) for f in finals for k in minus))
    out = {"status": COMPLETE if recorded >= expected else INCOMPLETE, "expected": expected, "recorded": recorded,
           "missing": max(expected - recorded, 0), "source": source}
    if recorded > expected:
        out["extra"] = recorded - expected
    return out


def _int(meta: dict[str, str], key: str) -> int | None:
    value = meta.get(key)
    return int(value) if value is not None and value.lstrip("-").isdigit() else None


NodeCounters = Mapping[str, Mapping[str, Any]] | Sequence[tuple[str, Mapping[str, Any]]]


def _pairs(node_counters: NodeCounters | None) -> list[tuple[str, Mapping[str, Any]]]:
    if node_counters is None:
        return []
    return list(node_counters.items()) if isinstance(node_counters, Mapping) else list(node_counters)


def _label(kind: str, limb: str | None) -> str:
    return kind if limb is None else f"{kind} ({limb})"


def completeness_block(data: SessionData, node_counters: NodeCounters | None = None) -> dict[str, Any]:
    """The `completeness` block of summary.json (module docstring). `node_counters` ((node kind, counters) pairs or
    node kind -> counters, e.g. a node's `--json` summary saved on its host: `sea-hil report --node-summary`) stand in
    for a final record the file lacks, so a recorder cut off before the edge's final statistics still says how much
    it missed. Several limbs: each limb's channels (`state.<limb>`, ...) against its own nodes' final records (their
    `node_id`), so one limb's surplus cannot hide another's shortfall."""
    finals = final_records(data)
    meta = data.metadata.get("sea-hil.final", {})
    can_tapped = bool(_int(meta, "can_frames")) or bool(data.messages.get("/can/raw"))
    limbs = recorded_limbs(data)
    channels: dict[str, dict[str, Any]] = {}
    never: list[str] = []
    supplied: list[str] = []
    pairs = _pairs(node_counters)
    if len(limbs) == 1:
        for kind in NODES:
            own = finals.get(kind, [])
            extra = [dict(c) for k, c in pairs if k == kind and c.get("node_id") in (None, limbs[0][1])][-1:] \
                if not own else []
            supplied += [kind] if extra else []
            never += [f"{kind} final stats"] if not own else []
            finals[kind] = own + extra
        channels.update(_limb_channels(data, finals["edge"], finals["controller"], can_tapped, ""))
    else:
        ctrl_by_node = any("node_id" in f for f in finals.get("controller", []))
        for name, node_id, _ in limbs:
            view = limb_view(data, name, node_id)
            mine = {kind: [f for f in finals.get(kind, []) if f.get("node_id") == node_id] for kind in NODES}
            for kind in NODES if ctrl_by_node else ("edge",):
                if not mine[kind]:
                    never.append(f"{kind} final stats ({name})")
                    mine[kind] = [dict(c) for k, c in pairs if k == kind and c.get("node_id") == node_id][-1:]
                    supplied += [_label(kind, name)] if mine[kind] else []
            channels.update(_limb_channels(view, mine["edge"], mine["controller"], can_tapped, f".{name}",
                                           downlink=ctrl_by_node))
        if not ctrl_by_node:   # controller records without the limb's node id (an outside controller): summed
            ctrl = finals.get("controller", [])
            recorded = _unique_count(data, "/zenoh/setpoint") + _unique_count(data, "/zenoh/voltage")
            if len(ctrl) < len(limbs):
                never.append(f"controller final stats ({len(limbs) - len(ctrl)} of {len(limbs)} limbs)")
                channels["downlink"] = _channel(recorded, [], (), "controller setpoints_sent of every limb")
            else:
                channels["downlink"] = _channel(recorded, ctrl, ("setpoints_sent",),
                                                "controller setpoints_sent, summed over the limbs")
    lost = _int(meta, "can_frames_missed") if can_tapped else None
    if lost:   # frames missing between those seen: counted against the CAN channel whatever the nodes say
        channels["can_frames"] = {"status": INCOMPLETE, "expected": (_int(meta, "can_frames") or 0) + lost,
                                  "recorded": _int(meta, "can_frames") or 0, "missing": lost,
                                  "source": "recorder can_frames_missed (sequence gaps)"}
    incomplete = [name for name, c in channels.items() if c["status"] == INCOMPLETE]
    unverified = [name for name, c in channels.items() if c["status"] == UNVERIFIED]
    file_finals = final_records(data)
    return {"complete": not incomplete and not unverified and not never, "incomplete": incomplete,
            "unverified": unverified, "channels": channels,
            "final_records": {node: len(recs) for node, recs in sorted(file_finals.items())},
            **({"counters_from_node_summaries": sorted(supplied)} if supplied else {}),
            "never_seen": never, "can_frames_lost": lost, "recorder_dropped": _int(meta, "dropped") or 0}


def _limb_channels(data: SessionData, edge: list[dict[str, Any]], ctrl: list[dict[str, Any]], can_tapped: bool,
                   suffix: str, downlink: bool = True) -> dict[str, dict[str, Any]]:
    """The channels of one limb's share of the recording (`suffix`: "" or ".<limb>") against its nodes' records."""
    channels = {
        # uplink_msgs counts the states the link emulator kept, also those still held in its delay queue at the end
        f"state{suffix}": _channel(_unique_count(data, "/zenoh/state"), edge, ("uplink_msgs",),
                                   "edge uplink_msgs - uplink_pending", minus=("uplink_pending",)),
    }
    if downlink:
        channels[f"downlink{suffix}"] = _channel(
            _unique_count(data, "/zenoh/setpoint") + _unique_count(data, "/zenoh/voltage"), ctrl,
            ("setpoints_sent",), "controller setpoints_sent")
    commands = sum(m.payload.get("kind") == "voltage" for m in data.messages.get("/can/command", []))
    if can_tapped:
        channels[f"can_command{suffix}"] = _channel(commands, edge, ("commands_sent", "arrival_commands"),
                                                    "edge commands_sent + arrival_commands")
    else:
        channels[f"can_command{suffix}"] = {"status": NOT_RECORDED, "expected": None, "recorded": 0, "missing": None,
                                            "source": "no CAN tap in this recording"}
    return channels


def completeness_lines(block: Mapping[str, Any]) -> list[str]:
    """One line per channel that is not complete (empty when the recording is complete): for tables and warnings."""
    out = []
    for name, c in block.get("channels", {}).items():
        if c["status"] == INCOMPLETE:
            out.append(f"{name}: {c['missing']} of {c['expected']} not recorded ({c['source']})")
        elif c["status"] == UNVERIFIED:
            out.append(f"{name}: unverified, {c['recorded']} recorded ({c['source']} never recorded)")
    out += [f"never seen: {what}" for what in block.get("never_seen", [])]
    if block.get("recorder_dropped"):
        out.append(f"recorder dropped {block['recorder_dropped']} records")
    return out
