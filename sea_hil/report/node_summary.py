"""A node's own result (issue 32): what `sea-hil edge`, `controller` or `record` saw, as a table or as JSON.

Each host of a distributed session ends with an answer of its own, like `sea-hil run`: the node's counters
(messages, rejections, faults), its view of the latency (the edge measures state published -> answer arrived), and
for the recorder whether its file is complete against the nodes' counters (`sea_hil.report.completeness`). The JSON
form validates against `NODE_SUMMARY_SCHEMA`; `sea-hil report` on the recording gives the whole session's summary.
"""
from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from typing import Any, TextIO

from rich.console import Console
from rich.table import Table

from sea_hil.report.completeness import COMPLETENESS_SCHEMA, completeness_lines

KINDS = ("plant", "edge", "controller", "recorder")
_NUMBER = {"type": "number"}
NODE_SUMMARY_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "sea-hil node summary (sea-hil plant | edge | controller | record --json)",
    "type": "object", "additionalProperties": False,
    "required": ["node", "finished", "counters", "warnings"],
    "properties": {
        "node": {"enum": list(KINDS)},
        "finished": {"type": "boolean"},      # controller: its cycles done; edge, recorder: stopped as asked
        "counters": {"type": "object", "additionalProperties": _NUMBER},   # the node's final stats record
        "latency_us": {"type": "object", "additionalProperties": False, "required": ["p50", "p99", "max"],
                       "properties": {k: _NUMBER for k in ("p50", "p99", "max")}},   # edge: state -> answer
        "warnings": {"type": "array", "items": {"type": "string"}},
        "recording": {"type": "string"},                     # recorder: the file
        "completeness": COMPLETENESS_SCHEMA,                 # recorder: the file against the nodes' counters
    }}

# (row label, counter keys shown as "a / b / ...") per node kind; keys a node does not have are left out
ROWS: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "edge": (("feedback samples", ("feedback_samples",)),
             ("states published / setpoints applied", ("uplink_msgs", "downlink_applied")),
             ("voltage commands sent (+ on arrival)", ("commands_sent", "arrival_commands")),
             ("loop overruns / late samples", ("loop_overruns", "late_samples"))),
    "controller": (("states handled / setpoints sent", ("states_handled", "setpoints_sent")),
                   ("ignored / unusable states", ("ignored_states", "unusable_states")),
                   ("state seq lost / reordered", ("state_seq_lost", "state_seq_reordered"))),
    "recorder": (("Zenoh messages / CAN frames", ("zenoh_msgs", "can_frames")),),
}
# counters that are a problem when non-zero (rejections, faults, losses)
WARN_KEYS: dict[str, tuple[str, ...]] = {
    "edge": ("rejected_frames", "rejected_samples", "payload_rejected", "unexpected_payloads", "stale_setpoints",
             "setpoints_out_of_envelope", "bus_errors", "controller_restarts", "late_setpoints", "seq_lost",
             "epoch_old", "epoch_foreign", "uplink_dropped", "downlink_dropped"),
    "controller": ("payload_rejected", "unexpected_payloads", "edge_restarts", "trajectory_mismatches",
                   "state_seq_lost", "epoch_old", "epoch_foreign", "recorder_unmatched"),
    "recorder": ("can_rejected", "can_frames_missed", "stats_rejected", "payload_rejected_total", "dropped",
                 "write_errors", "can_tap_unfinished"),
}


def node_summary(kind: str, counters: Mapping[str, Any], *, finished: bool,
                 completeness: Mapping[str, Any] | None = None, recording: str | None = None) -> dict[str, Any]:
    """The node's result: its numeric counters, latency (when it measured one), warnings."""
    nums = {k: v for k, v in counters.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    out: dict[str, Any] = {"node": kind, "finished": finished, "counters": nums}
    lat = {k: nums.get(f"latency_{k}_us", -1.0) for k in ("p50", "p99", "max")}
    if all(v >= 0 for v in lat.values()):
        out["latency_us"] = {k: float(v) for k, v in lat.items()}
    warnings = [f"{k.replace('_', ' ')}: {nums[k]:g}" for k in WARN_KEYS.get(kind, ()) if nums.get(k)]
    if completeness is not None:
        out["completeness"] = dict(completeness)
        warnings += completeness_lines(completeness)
    if recording is not None:
        out["recording"] = recording
    out["warnings"] = warnings
    return out


def node_rows(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    kind, nums = summary["node"], summary["counters"]
    rows = [("node", f"{kind}, {'finished' if summary['finished'] else 'stopped'}")]
    for label, keys in ROWS.get(kind, ()):
        present = [k for k in keys if k in nums]
        if present:
            rows.append((label, " / ".join(f"{nums[k]:g}" for k in present)))
    lat = summary.get("latency_us")
    rows.append(("latency p50 / p99 / max", "not measured" if lat is None else
                 f"{lat['p50'] / 1000:.2f} / {lat['p99'] / 1000:.2f} / {lat['max'] / 1000:.2f} ms"))
    if "recording" in summary:
        rows.append(("recording", summary["recording"]))
    comp = summary.get("completeness")
    if comp is not None:
        rows.append(("recording complete", "yes" if comp["complete"] else "no"))
    rows.append(("warnings", "\n".join(summary["warnings"]) or "none"))
    return rows


def print_node_summary(summary: Mapping[str, Any], *, as_json: bool = False, command: str = "",
                       stream: TextIO | None = None) -> None:
    """The node's table (or, `as_json`, its JSON on one line) on `stream` (stdout)."""
    out = stream if stream is not None else sys.stdout
    if as_json:
        print(json.dumps(summary, sort_keys=True), file=out, flush=True)
        return
    table = Table(title=f"sea-hil {command or summary['node']}", show_header=False, title_justify="left")
    table.add_column("what", style="bold")
    table.add_column("value")
    for what, value in node_rows(summary):
        table.add_row(what, value)
    Console(file=out, width=120).print(table)


