"""Limbs as data: which limbs a session emulates and on which CAN bus each one sits.

`session_limbs(cfg, n, node_id)` is the one place the list is made: `[[limbs]]` of the config as given, else the
default limb (`[zenoh] limb`, `node_id`, `[can] interface`) -- once, or `n` times with `--limbs N`
(`expand_limbs`). Expanded limbs get node ids `node_id, node_id + 1, ...`, names `<stem>1..` (`limb1`, `limb2`,
...: the first keeps the 1-limb keys) and buses from the bus-load model: a bus carries as many limbs as fit below
`MAX_BUS_LOAD` of its capacity (`limbs_per_bus`, the planned worst-case load of one limb's frames for the [can]
profile, `sea_hil.protocol.bus_timing.planned_load_pct`); classic CAN at 1 Mbit/s: 51.1 % a limb, one limb per
bus (1.96 would fit at 100 %); CAN FD at 1 / 5 Mbit/s: 16.4 % a limb, four limbs per bus.
Bus channels count up from the configured one (`bus_specs`): `virtual:NAME` -> `virtual:NAME0, NAME1, ...`,
`socketcan:vcan0` -> `vcan0, vcan1, ...`, `ipc:NAME` -> `ipc:NAME0, NAME1, ...`, `udp_multicast:239.74.163.2` -> `.2, .3, ...`;
one bus keeps its spec.

The cia402 profile (`cia402_limbs`): each limb is a (hip, knee) pair of CANopen nodes, `[can.cia402] node_ids` in
limb order (one pair per limb), and its `node_id` is its hip node's (the edge's and the recording's name for the
limb). One limb per bus: the edge is the bus's CANopen master and SYNC producer, and a second limb on the same bus
would need one master for all four nodes and a SYNC period of at least 1.5 ms (docs/cia402.md, Bus budget), which
is not built: `--limbs N` puts each limb on a bus of its own, a config that shares a bus is refused.
"""
from __future__ import annotations

import ipaddress
import math
import re
from dataclasses import dataclass
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.config.wire_names import parse_can_spec
from sea_hil.errors import ConfigError
from sea_hil.protocol.bus_timing import planned_load_pct
from sea_hil.protocol.can_frames import NODE_ID_MAX
from sea_hil.protocol.cia402_budget import budget

MAX_BUS_LOAD = 0.8   # planned worst-case load of a bus at most (a session warns above 80 %, issue 17)


@dataclass(frozen=True)
class Limb:
    name: str
    node_id: int
    bus: str


def limb_load_pct(cfg: SeaHilConfig) -> float:
    """Planned worst-case load (%) of one limb on its bus, for the configured profile (classic or FD):
    `sea_hil.protocol.bus_timing.planned_load_pct` (its feedback and voltage frames per sample, its heartbeats)."""
    return planned_load_pct(cfg.can, (1,))


def limbs_per_bus(cfg: SeaHilConfig, max_load: float = MAX_BUS_LOAD) -> int:
    """How many limbs one bus carries below `max_load` of its capacity (at least one; the cia402 profile: one, its
    edge is the bus's SYNC producer for one limb)."""
    if cfg.can.profile == "cia402":
        return 1
    return max(1, math.floor(1e-9 + 100.0 * max_load / limb_load_pct(cfg)))


def bus_specs(spec: str, count: int) -> list[str]:
    """`count` bus specs counting up from `spec` (see the module docstring); `[spec]` for one."""
    if count == 1:
        return [spec]
    interface, channel = parse_can_spec(spec)
    if interface == "udp_multicast":
        base = ipaddress.ip_address(channel)
        return [f"{interface}:{base + i}" for i in range(count)]
    m = re.fullmatch(r"(.*?)(\d*)", channel)
    assert m is not None
    stem, first = m.group(1), int(m.group(2) or 0)
    out = [f"{interface}:{stem}{first + i}" for i in range(count)]
    for s in out:
        parse_can_spec(s)   # e.g. a socketcan name grown past 15 characters
    return out


def _stem(name: str) -> str:
    return name.rstrip("0123456789") or name


def expand_limbs(cfg: SeaHilConfig, n: int, node_id: int = 1, spec: str | None = None) -> tuple[Limb, ...]:
    """The default limb `n` times: node ids from `node_id`, names `<stem>1..n`, spread over as many buses (counted
    up from `spec`, default `[can] interface`) as the bus-load model needs; limbs fill a bus before the next."""
    if n < 1:
        raise ConfigError(f"--limbs must be >= 1, got {n}")
    if node_id + n - 1 > NODE_ID_MAX:
        raise ConfigError(f"{n} limbs from node id {node_id} exceed the largest node id {NODE_ID_MAX}")
    spec = spec or cfg.can.interface
    if n == 1:
        return (Limb(cfg.zenoh.limb, node_id, spec),)
    per_bus = limbs_per_bus(cfg)
    buses = bus_specs(spec, math.ceil(n / per_bus))
    stem = _stem(cfg.zenoh.limb)
    return tuple(Limb(f"{stem}{i + 1}", node_id + i, buses[i // per_bus]) for i in range(n))


def session_limbs(cfg: SeaHilConfig, n: int | None = None, node_id: int = 1, spec: str | None = None
                  ) -> tuple[Limb, ...]:
    """The session's limbs: `[[limbs]]` when configured (then `n`, if given, must not contradict it), else the
    default limb expanded `n` times (once without `n`)."""
    if cfg.limbs:
        if n is not None and n != len(cfg.limbs):
            raise ConfigError(f"--limbs {n} contradicts the {len(cfg.limbs)} [[limbs]] of the config")
        limbs = tuple(Limb(lc.name, lc.node_id, lc.bus or spec or cfg.can.interface) for lc in cfg.limbs)
    else:
        limbs = expand_limbs(cfg, n or 1, node_id, spec)
    return cia402_limbs(cfg, limbs) if cfg.can.profile == "cia402" else limbs


def cia402_pairs(cfg: SeaHilConfig) -> list[tuple[int, int]]:
    """`[can.cia402] node_ids` as (hip, knee) pairs, one per limb in limb order."""
    ids = cfg.can.cia402.node_ids
    return [(ids[i], ids[i + 1]) for i in range(0, len(ids), 2)]


def cia402_limbs(cfg: SeaHilConfig, limbs: tuple[Limb, ...]) -> tuple[Limb, ...]:
    """The limbs of a cia402 session, each named by its hip node (module docstring); `ConfigError` (one line) for a
    pair count that does not match the limbs, two limbs on one bus, or a SYNC rate whose frames do not fit the bus."""
    pairs = cia402_pairs(cfg)
    if len(pairs) != len(limbs):
        raise ConfigError(f"can.cia402.node_ids: {len(pairs)} (hip, knee) pair(s) {list(cfg.can.cia402.node_ids)} "
                          f"for {len(limbs)} limb(s): give one pair per limb, e.g. node_ids = "
                          f"{[n for i in range(len(limbs)) for n in (2 * i + 1, 2 * i + 2)]}")
    for bus, on in buses_of(limbs).items():
        if len(on) > 1:
            raise ConfigError(f"cia402 profile: limbs {', '.join(limb.name for limb in on)} share CAN bus {bus}; "
                              "one limb per bus (its edge is the bus's SYNC producer; two limbs on one bus need one "
                              "master for all their nodes and a SYNC period >= 1.5 ms, not built): give each limb "
                              "its own bus ([[limbs]] bus, or --limbs N; docs/cia402.md)")
    b = budget(1, cfg.can.feedback_rate_hz, cfg.can.bitrate_bps)
    if b.load_pct_worst + b.background_pct_worst > 100.0:
        raise ConfigError(f"can.feedback_rate_hz: one cia402 limb's frames per SYNC at {cfg.can.feedback_rate_hz:g} "
                          f"Hz need {b.load_pct_worst + b.background_pct_worst:.1f} % of the {cfg.can.bitrate_bps} "
                          "bit/s bus (worst case, docs/cia402.md Bus budget): lower the SYNC rate")
    return tuple(Limb(limb.name, hip, limb.bus) for limb, (hip, _) in zip(limbs, pairs, strict=True))


def buses_of(limbs: tuple[Limb, ...]) -> dict[str, tuple[Limb, ...]]:
    """Bus spec -> its limbs, in order of first appearance."""
    out: dict[str, tuple[Limb, ...]] = {}
    for limb in limbs:
        out[limb.bus] = out.get(limb.bus, ()) + (limb,)
    return out


def limb_config(cfg: SeaHilConfig, limb: Limb) -> SeaHilConfig:
    """The config of one limb's nodes: its Zenoh key chunk, its node id and bus (cia402: its node pair, the one
    whose hip is the limb's node id)."""
    can: dict[str, Any] = {"interface": limb.bus, "node_ids": (limb.node_id,)}
    if cfg.can.profile == "cia402":
        pair = next((p for p in cia402_pairs(cfg) if p[0] == limb.node_id), None)
        if pair is not None:
            can["cia402"] = cfg.can.cia402.model_copy(update={"node_ids": pair})
    return cfg.model_copy(update={"zenoh": cfg.zenoh.model_copy(update={"limb": limb.name}),
                                  "can": cfg.can.model_copy(update=can), "limbs": ()})
