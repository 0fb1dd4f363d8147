"""The JSON Schema (draft 2020-12) of summary.json, the same for `simulate`, `run` and `report` (docs/session.md).

A key that is not listed here is an error, so a new field has to be placed deliberately: deterministic ones at the
top level (or in `edge`), anything derived from wall-clock or CPU time under `timing`. Tests validate every summary
they produce against it (with the `jsonschema` package of the dev extra; nothing at run time needs it).
"""
from __future__ import annotations

from typing import Any

from sea_hil.report.completeness import COMPLETENESS_SCHEMA

_NUMBER = {"type": "number"}
_COUNT = {"type": "integer", "minimum": 0}
_PAIR = {"type": "array", "items": _NUMBER, "minItems": 2, "maxItems": 2}


def _object(props: dict[str, Any], required: tuple[str, ...] | None = None) -> dict[str, Any]:
    """A closed object: exactly `props` (all required unless `required` says which)."""
    return {"type": "object", "properties": props, "required": list(props if required is None else required),
            "additionalProperties": False}


TRANSMISSIONS = _object({k: _COUNT for k in ("downlink_msgs", "downlink_bytes", "uplink_msgs", "uplink_bytes",
                                              "total_msgs", "total_bytes")})   # total = uplink + downlink
TRACKING = _object({"max_abs_error_rad": _PAIR, "rms_error_rad": _PAIR})
_US3 = _object({k: _NUMBER for k in ("p50", "p99", "max")})
CAN_BUS = _object({"bitrate_bps": _COUNT, "data_bitrate_bps": _COUNT, "frames": _COUNT, "load_pct": _NUMBER,
                   "per_id": {"type": "array", "items": _object({"can_id": _COUNT, "frames": _COUNT,
                                                                 "queue_us": _US3, "latency_us": _US3})}})
# the host's empty-loop floor measured at start-up of a real-time run (sea_hil/runtime/timer_floor.py)
FLOOR = _object({"ticks": _COUNT, "misses": _COUNT, "miss_pct": _NUMBER, "lateness_us_p99": _NUMBER,
                 "duration_s": _NUMBER})
_NULLABLE_NUMBER = {"type": ["number", "null"]}
DRIVE_FAULT = _object({"node_id": _COUNT, "t_s": _NULLABLE_NUMBER, "state": {"enum": ["FAULT", "ESTOP"]},
                       "flags": {"type": "array", "items": {"type": "string"}}, "in_fault_s": _NULLABLE_NUMBER,
                       "cleared": {"type": "boolean"}, "clear_policy": {"type": "string"},
                       "after_session": {"type": "boolean"}, "source": {"enum": ["can", "edge"]}}, required=("node_id", "t_s", "state", "flags",
                                                                       "in_fault_s", "cleared", "clear_policy"))
# sea_hil/verdict/rules.py: a reason has its code, severity, message, figure and threshold, and may say more
REASON = {"type": "object", "required": ["code", "severity", "message", "value", "threshold"],
          "properties": {"code": {"type": "string"}, "severity": {"enum": ["degraded", "invalid"]},
                         "message": {"type": "string"}}}
VERDICT = _object({"status": {"enum": ["ok", "degraded", "invalid"]}, "reasons": {"type": "array", "items": REASON}})
RECORDING = _object({"dropped": _COUNT, "write_errors": _COUNT, "can_frames_missed": _COUNT,
                     "can_command_gaps": _COUNT, "recorder_dropped_ops": _COUNT, "can_tap_unfinished": _COUNT, "lost": _COUNT,
                     "complete": {"type": "boolean"}})
TIMING = _object({
    "cpu_s": _NUMBER,                                                        # offline
    "wall_s": _NUMBER,                                                       # `run` (not `report`)
    "latency_us": _object({k: _NUMBER for k in ("min", "p50", "p90", "p99", "max")}),   # of the first limb
    "latency_samples": _COUNT,
    "edge": {"type": "object", "additionalProperties": _NUMBER},             # wall-time-derived edge counters
    "driver": _object({"ticks": _COUNT, "tick_misses": _COUNT, "floor": FLOOR},   # `run`: summed over the buses'
                      required=("ticks", "tick_misses")),                    # drivers; floor: real time only
    "sync": _object({"syncs": _COUNT, "misses": _COUNT}),                  # cia402: summed over the limbs' edges
    "can_bus": {"type": "object", "additionalProperties": CAN_BUS},          # [can] emulate_bitrate, per bus spec
    "rejections": {"type": "object", "additionalProperties": _COUNT},       # sessions: wall-time-derived classes
}, required=())
LINK_LOSSES = _object({"uplink_beyond_model": _COUNT})
LATENCY = _object({k: _NUMBER for k in ("min", "p50", "p90", "p99", "max")})
LIMB = _object({"limb": {"type": "string"}, "node_id": _COUNT, "bus": {"type": "string"},
                "transmissions": TRANSMISSIONS, "tracking": TRACKING,
                "timing": _object({"latency_us": LATENCY}),                # the limb's wall-time-derived part
                # several limbs: the limb's own deterministic edge counters, rejections and link losses (the
                # verdict's per limb)
                "edge": {"type": "object", "additionalProperties": _NUMBER},
                "rejections": {"type": "object", "additionalProperties": _COUNT},
                "link_losses": LINK_LOSSES},
               required=("limb", "node_id", "bus", "transmissions", "tracking", "timing"))
LIMBS_TOTAL = _object({"limbs": _COUNT, "buses": _COUNT, "transmissions": TRANSMISSIONS, "tracking": TRACKING})

SUMMARY_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "sea-hil summary.json",
    **_object({
        "controller": {"enum": ["et", "tt"]},
        "duration_s": _NUMBER,
        "transmissions": TRANSMISSIONS,
        "events_by_reason": {"type": "object", "additionalProperties": _COUNT},
        "tracking": TRACKING,
        "inter_event_s": _object({k: _NUMBER for k in ("min", "median", "max")}),
        "max_abs_voltage_v": _PAIR,
        "timing": TIMING,
        "verdict": VERDICT,                                                  # docs/verdict.md
        # offline only
        "saturated_steps": _COUNT,
        "quantised": {"type": "boolean"},
        "inner_steps": _COUNT,                                               # `simulate`
        # sessions and the offline session engine
        "drive_faults": {"type": "array", "items": DRIVE_FAULT},
        "recording": RECORDING,                                              # recorded sessions: recorder losses
        "link_losses": LINK_LOSSES,                                          # with the controller's final stats
        # sessions only
        "lead_in": _object({"duration_s": _NUMBER, **TRANSMISSIONS["properties"], "tracking": TRACKING}),
        "uplink_outside_msgs": _COUNT,
        "edge": {"type": "object", "additionalProperties": _NUMBER},         # deterministic edge counters
        "rejections": {"type": "object", "additionalProperties": _COUNT},   # sessions: count per rejection class
        "limbs": {"type": "array", "items": LIMB, "minItems": 1},           # sessions: every limb
        "limbs_total": LIMBS_TOTAL,                                           # sessions: all limbs
        "lockstep": {"type": "boolean"},                                     # `run`, `report`
        "inner": {"enum": ["edge", "remote"]},                               # `run` only
        "completeness": COMPLETENESS_SCHEMA,                                 # from a recording: `run`, `report`
    }, required=("controller", "duration_s", "transmissions", "events_by_reason", "tracking", "inter_event_s",
                 "max_abs_voltage_v", "timing", "verdict")),
    "anyOf": [{"required": ["saturated_steps", "quantised"]},                  # offline
              {"required": ["lead_in", "uplink_outside_msgs", "edge", "limbs", "limbs_total"]}],       # session
}
