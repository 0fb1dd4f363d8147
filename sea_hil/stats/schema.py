"""The one stats schema: every node's counters, on the Zenoh `stats` key, in the recorder's `/stats` channel and
in `sea-hil run`'s final record, are one flat JSON object (docs/recording.md, "Statistics"):

- `node`: which node wrote it (`plant`, `edge`, `controller`, `recorder`), a string;
- `final`: true for the node's last record of a session (written when it stops), a boolean;
- `t_ns`: when the record was taken, the writer's `time.monotonic_ns()`, an integer;
- every other field: a number (integer or float; null for a non-finite value), names `[a-z0-9_]`, units in the
  name (`_us`, `_s`, `_bytes`).

`stats_record` builds a record (and refuses a non-numeric field: a bug in the node, not bad input);
`validate_stats` checks one received from outside (`StatsError`); `STATS_JSON_SCHEMA` is the same rule as a
JSON schema (draft 2020-12), which the recorder registers for `/stats`.
"""
from __future__ import annotations

import math
import numbers
import re
import time
from collections.abc import Mapping
from typing import Any

from sea_hil.errors import SeaHilError

NODE_KINDS = ("plant", "edge", "controller", "recorder")
ENVELOPE = ("node", "final", "t_ns")
_FIELD = re.compile(r"^[a-z][a-z0-9_]*$")

STATS_PROPERTIES: dict[str, Any] = {"node": {"enum": list(NODE_KINDS)}, "final": {"type": "boolean"},
                                    "t_ns": {"type": "integer"}}
STATS_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema", "title": "sea_hil.Stats",
    "description": "Counters of one node (sea_hil.stats.schema): node, final, t_ns, then numbers only.",
    "type": "object", "properties": STATS_PROPERTIES, "required": list(ENVELOPE),
    "propertyNames": {"pattern": _FIELD.pattern}, "additionalProperties": {"type": ["number", "null"]}}


class StatsError(SeaHilError):
    """A stats record that does not follow the stats schema."""


def _number(v: object) -> bool:
    return v is None or (isinstance(v, numbers.Real) and not isinstance(v, bool)
                         and (not isinstance(v, float) or math.isfinite(v)))


def validate_stats(record: Mapping[str, Any]) -> None:
    """Raise `StatsError` unless `record` follows the stats schema (see the module docstring)."""
    if not isinstance(record, Mapping):
        raise StatsError(f"stats record must be an object, got {type(record).__name__}")
    missing = [k for k in ENVELOPE if k not in record]
    if missing:
        raise StatsError(f"stats record misses {missing}")
    if record["node"] not in NODE_KINDS:
        raise StatsError(f"stats node must be one of {NODE_KINDS}, got {record['node']!r}")
    if not isinstance(record["final"], bool):
        raise StatsError(f"stats final must be a boolean, got {record['final']!r}")
    if not isinstance(record["t_ns"], int) or isinstance(record["t_ns"], bool):
        raise StatsError(f"stats t_ns must be an integer, got {record['t_ns']!r}")
    for k, v in record.items():
        if not isinstance(k, str) or not _FIELD.match(k):
            raise StatsError(f"stats field name {k!r} must match {_FIELD.pattern}")
        if k not in ENVELOPE and not _number(v):
            raise StatsError(f"stats field {k} must be a finite number or null, got {v!r}")


def stats_record(node: str, fields: Mapping[str, Any], *, final: bool = False,
                 t_ns: int | None = None) -> dict[str, Any]:
    """One record of node kind `node` from its flat numeric `fields` (validated)."""
    clash = [k for k in fields if k in ENVELOPE]
    if clash:
        raise StatsError(f"stats fields {clash} are reserved for the envelope")
    record = {"node": node, "final": bool(final), "t_ns": time.monotonic_ns() if t_ns is None else t_ns, **fields}
    validate_stats(record)
    return record
