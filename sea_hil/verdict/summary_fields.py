"""Reading summary.json's fields as every reader of it does (the verdict's rules, the end-of-run table): `field`
also finds a field under `timing` (the wall-time-derived ones live there), `sync_periods` the cia402 profile's SYNC
deadlines wherever the summary keeps them. Pure."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

_MISSING = object()


def field(summary: Mapping[str, Any], *path: str, default: Any = None) -> Any:
    """`summary[path...]`, also looked up under `summary["timing"]` (timing-derived fields live there), else
    `default`."""
    for root in (summary, summary.get("timing")):
        node: Any = root
        for key in path:
            node = node.get(key, _MISSING) if isinstance(node, Mapping) else _MISSING
        if node is not _MISSING:
            return node
    return default


def sync_periods(summary: Mapping[str, Any]) -> tuple[int, int] | None:
    """The cia402 profile's SYNC deadlines of a run: (periods missed by the edges' SYNC producers, periods due =
    SYNCs sent + missed), from `timing.sync` (every limb), else the first limb's edge counters `cia402_sync_misses`
    and `cia402_syncs` (timing.edge and edge); None for a run without them (the sea profile, the offline engine)."""
    sync = (summary.get("timing") or {}).get("sync")
    if isinstance(sync, Mapping):
        misses, syncs = sync.get("misses"), sync.get("syncs")
    else:
        edge = {**(summary.get("edge") or {}), **((summary.get("timing") or {}).get("edge") or {})}
        misses, syncs = edge.get("cia402_sync_misses"), edge.get("cia402_syncs")
    if not isinstance(misses, (int, float)) or not isinstance(syncs, (int, float)) or syncs + misses <= 0:
        return None
    return int(misses), int(syncs + misses)
