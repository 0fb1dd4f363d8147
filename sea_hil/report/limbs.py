"""Every limb of a session in summary.json: `limbs` (one entry per limb: name, node id, bus, transmissions, tracking,
and under its own `timing` the closed-loop latency), `limbs_total` (all limbs: summed transmissions, the worst
tracking of any limb), `timing.driver` (driver ticks and tick misses, summed over the buses' drivers) and, in the
cia402 profile, `timing.sync` (SYNCs sent and SYNC periods missed, summed over the limbs' edges).

A limb's share of the recording (`limb_view`): Zenoh messages whose key names the limb (`<prefix>/<limb>/...`), CAN
messages and final edge stats of its node id, everything else shared. The limb list comes from the recording's
`sea-hil.limbs` metadata (`sea-hil run` writes it); a recording without it (older files, the offline session engine)
has one limb, named by its state key, node id of its feedback frames, bus from `sea-hil.session`'s `can`.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from sea_hil.recorder.reader import SessionData

META_LIMBS = "sea-hil.limbs"


def recorded_limbs(data: SessionData) -> list[tuple[str, int, str]]:
    """(name, node id, bus) of every limb of the recording, in order."""
    meta = data.metadata.get(META_LIMBS)
    if meta:
        out = []
        for name, value in meta.items():
            node_id, _, bus = value.partition(" ")
            out.append((name, int(node_id), bus))
        return out
    states = data.messages.get("/zenoh/state", [])
    feedback = data.messages.get("/can/feedback", [])
    limb = str(states[0].payload.get("key", "?/limb1/state")).split("/")[-2] if states else "limb1"
    node = int(feedback[0].payload.get("node_id", 1)) if feedback else 1
    return [(limb, node, data.metadata.get("sea-hil.session", {}).get("can", ""))]


def _belongs(payload: dict[str, Any], name: str, node_id: int) -> bool:
    key = payload.get("key")
    if isinstance(key, str) and key.count("/") >= 2:
        return key.split("/")[-2] == name
    nid = payload.get("node_id")
    return nid is None or nid == node_id


def limb_view(data: SessionData, name: str, node_id: int) -> SessionData:
    """The recording as seen by one limb (see the module docstring)."""
    msgs = {t: [m for m in ms if _belongs(m.payload, name, node_id)] for t, ms in data.messages.items()}
    return replace(data, messages=msgs)


def limb_entry(name: str, node_id: int, bus: str, summary: dict[str, Any], *, counters: bool = False,
               link_losses: dict[str, int] | None = None) -> dict[str, Any]:
    """One `limbs` entry from that limb's summary; with `counters` (a session of several limbs) also the limb's own
    edge counters, rejections and `link_losses` (when its controller's final stats are recorded), which the verdict
    judges per limb (the 1-limb layout has them at the top level)."""
    out = {"limb": name, "node_id": node_id, "bus": bus, "transmissions": summary["transmissions"],
           "tracking": summary["tracking"], "timing": {"latency_us": summary["timing"]["latency_us"]}}
    if counters:
        out.update(edge=summary["edge"], rejections=summary["rejections"])
        if link_losses is not None:
            out["link_losses"] = link_losses
    return out


def limbs_total(entries: list[dict[str, Any]]) -> dict[str, Any]:
    """All limbs: counts, distinct buses, summed transmissions, the worst tracking error of any limb per joint."""
    tx = {k: sum(e["transmissions"][k] for e in entries) for k in entries[0]["transmissions"]}
    worst = {k: [max(e["tracking"][k][j] for e in entries) for j in (0, 1)] for k in entries[0]["tracking"]}
    return {"limbs": len(entries), "buses": len({e["bus"] for e in entries}), "transmissions": tx,
            "tracking": worst}


META_FLOOR = "sea-hil.host_floor"   # real time: the host's empty-loop floor measured at start-up (sea_hil/session/run.py)


def driver_block(data: SessionData) -> dict[str, Any] | None:
    """Driver ticks and tick misses (real time: deadlines skipped) from the final metadata, None when not recorded;
    with the host's floor measured at start-up (`floor`: ticks, misses, miss_pct, lateness p99, duration) when the
    recording has it."""
    final = data.metadata.get("sea-hil.final", {})
    if "plant_ticks" not in final:
        return None
    out: dict[str, Any] = {"ticks": int(final["plant_ticks"]), "tick_misses": int(final.get("plant_overruns", 0))}
    floor = data.metadata.get(META_FLOOR)
    if floor:
        out["floor"] = {"ticks": int(floor["ticks"]), "misses": int(floor["misses"]),
                        "miss_pct": float(floor["miss_pct"]), "lateness_us_p99": float(floor["lateness_us_p99"]),
                        "duration_s": float(floor["duration_s"])}
    return out


def sync_block(per_limb: list[dict[str, Any]]) -> dict[str, int] | None:
    """The cia402 profile's SYNCs over every limb's edge (each its bus's SYNC producer): `syncs` sent (`edge.
    cia402_syncs`), periods `misses`ed (`timing.edge.cia402_sync_misses`, real time); None for other sessions."""
    syncs = [s["edge"].get("cia402_syncs") for s in per_limb]
    if any(not isinstance(n, int) for n in syncs):
        return None
    misses = sum(int(s["timing"]["edge"].get("cia402_sync_misses", 0)) for s in per_limb)
    return {"syncs": sum(int(n) for n in syncs), "misses": misses}
