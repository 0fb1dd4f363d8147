"""The nodes of N limbs in `sea-hil run`'s host process, bus by bus (`sea_hil.session.limbs` says which limb sits on
which bus): per bus one driver node serving all its limbs' node ids (`PlantNode`, one thread, one schedule), one edge
(an `EdgeNode` when the bus carries one limb, as before; an `EdgeMux` hosting one edge core per limb otherwise) and
one recorder tap; the first tap also records Zenoh. One limb gives exactly the composition of the 1-limb session.
With `driver_dir` (real time, `[timing] driver_process`) each driver is a process of its own instead
(`sea_hil.session.driver_process`; its config file in `driver_dir`), on buses that cross processes; edges and taps
stay here.
"""
from __future__ import annotations

import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_mux import EdgeMux
from sea_hil.protocol.merged_bus import MergedBus, can_merge
from sea_hil.recorder.writer import RecordSink
from sea_hil.session.builder import SessionBuilder
from sea_hil.session.driver_process import DriverProcess
from sea_hil.session.limbs import Limb, buses_of, limb_config


@dataclass
class LimbNodes:
    limbs: tuple[Limb, ...]
    plants: list[Any] = field(default_factory=list)      # one per bus, in bus order (a `DriverProcess` or a node)
    edges: list[Any] = field(default_factory=list)       # one EdgeNode (core) per limb, in limb order
    runners: list[Any] = field(default_factory=list)     # what runs a thread: a bus's EdgeNode or EdgeMux
    taps: list[Any] = field(default_factory=list)        # one recorder tap bus per bus

    @property
    def buses(self) -> list[str]:
        return list(buses_of(self.limbs))

    def final_stats(self) -> dict[str, Any]:
        """The drivers' counters for the recording's final metadata: totals (`plant_ticks`, `plant_overruns`, the
        1-limb keys) and, with several buses, per bus (`bus<i>_plant_ticks`, ...). None of them when a driver process
        gave no result (it was ended without one): no count is made up."""
        stats = [p.stats for p in self.plants]
        if any(s is None for s in stats):
            return {}
        out: dict[str, Any] = {"plant_overruns": sum(s.overruns for s in stats),
                               "plant_ticks": sum(s.ticks for s in stats)}
        if len(stats) > 1:
            for i, s in enumerate(stats):
                out.update({f"bus{i}_plant_ticks": s.ticks, f"bus{i}_plant_overruns": s.overruns})
        return out

    def driver_processes(self) -> list[DriverProcess]:
        return [p for p in self.plants if isinstance(p, DriverProcess)]

    def metadata(self) -> dict[str, str]:
        """`sea-hil.limbs` metadata: limb name -> "node_id bus" (the summary's limb table reads it back)."""
        return {limb.name: f"{limb.node_id} {limb.bus}" for limb in self.limbs}


def build_limb_nodes(b: SessionBuilder, session: Any, limbs: tuple[Limb, ...], inner: str,
                     mode: str = "et", driver_dir: Path | None = None) -> LimbNodes:
    """Open every bus's handles and build its plant and edge (owned by `b`); nothing is started. Real time with
    several buses (and `[timing] merge_buses`): one driver, one edge and one tap for all buses (`_merged`). With
    `driver_dir`, each driver a `DriverProcess` (spawned, held until `start`; no handle of its bus here)."""
    nodes = LimbNodes(limbs)
    groups = buses_of(limbs)
    # plant (none here for a driver process), edge, recorder tap
    handles = {spec: (None if driver_dir else b.bus(spec), b.bus(spec), b.bus(spec)) for spec in groups}
    if _merged(b, nodes, handles, session, inner, mode, driver_dir):
        return nodes
    for i, (spec, group) in enumerate(groups.items()):
        plant_bus, edge_bus, tap = handles[spec]
        nodes.taps.append(tap)   # cia402: the tap decodes CANopen (sea_hil.recorder.can_tap, the session's config)
        # cia402 (one limb per bus, sea_hil.session.limbs): the drive of that limb's node pair
        plant_cfg = limb_config(b.cfg, group[0]) if b.cfg.can.profile == "cia402" else None
        ids = tuple(limb.node_id for limb in group)
        if driver_dir is not None:
            cfg = plant_cfg or b.cfg.model_copy(update={"can": b.cfg.can.model_copy(update={"interface": spec})})
            served = plant_cfg.can.cia402.node_ids if plant_cfg is not None else ids
            name = "plant.toml" if len(groups) == 1 else f"plant_bus{i}.toml"
            nodes.plants.append(_driver_process(b, cfg, driver_dir / name, tuple((n, spec) for n in served)))
        else:
            assert plant_bus is not None
            nodes.plants.append(b.plant(plant_bus, ids, cfg=plant_cfg))
        edges = [b.edge(edge_bus, session, limb.node_id, inner=inner, cfg=limb_config(b.cfg, limb), mode=mode)
                 for limb in group]
        nodes.edges += edges
        nodes.runners += edges if len(edges) == 1 else [b.add(EdgeMux(edge_bus, edges, workers=b.lockstep))]
    return nodes


def _driver_process(b: SessionBuilder, cfg: SeaHilConfig, path: Path, routes: tuple[tuple[int, str], ...]
                    ) -> DriverProcess:
    proc = DriverProcess(cfg, path, routes)
    b.callback(proc.close)   # every exit path ends it
    return proc


def _merged(b: SessionBuilder, nodes: LimbNodes, handles: dict[str, tuple[Any, Any, Any]], session: Any,
            inner: str, mode: str, driver_dir: Path | None = None) -> bool:
    """Compose one `PlantNode` serving every limb of every bus, one `EdgeMux` serving every edge core and one
    recorder tap, each over a `MergedBus` of the buses' handles (`sea_hil.protocol.merged_bus`): the threads of the
    session no longer grow with the buses (docs/timing.md "Where the CPU goes"). Only in real time, with several
    buses, distinct node ids and buses that can be merged, not in the cia402 profile; False (nothing built) otherwise. Lockstep keeps one node
    per bus, so no lockstep result can change. With `driver_dir`, the one driver is a `DriverProcess` serving every
    limb on its own bus (`sea-hil plant` with one `--can` per `--node`: its merged bus)."""
    limbs = nodes.limbs
    ids = [limb.node_id for limb in limbs]
    here = range(1, 3) if driver_dir is not None else range(3)   # the handles of this process
    if (b.lockstep or len(handles) < 2 or not b.cfg.timing.merge_buses or len(set(ids)) != len(ids)
            or b.cfg.can.profile == "cia402"   # a SYNC producer per bus: frames of one bus name no limb
            or not all(can_merge([h[k] for h in handles.values()]) for k in here)):
        return False
    edge_bus, tap = (MergedBus({limb.node_id: handles[limb.bus][k] for limb in limbs}) for k in (1, 2))
    nodes.taps.append(tap)
    if driver_dir is not None:
        nodes.plants.append(_driver_process(b, b.cfg, driver_dir / "plant.toml",
                                            tuple((limb.node_id, limb.bus) for limb in limbs)))
    else:
        nodes.plants.append(b.plant(MergedBus({limb.node_id: handles[limb.bus][0] for limb in limbs}), tuple(ids)))
    nodes.edges += [b.edge(edge_bus, session, limb.node_id, inner=inner, cfg=limb_config(b.cfg, limb), mode=mode)
                    for limb in limbs]
    nodes.runners.append(b.add(EdgeMux(edge_bus, nodes.edges)))
    return True


def start(nodes: LimbNodes) -> None:
    for node in (*nodes.plants, *nodes.runners):
        node.start()


def stop_and_join(nodes: LimbNodes) -> None:
    for node in (*nodes.plants, *nodes.runners):
        node.stop()
    for node in (*nodes.plants, *nodes.runners):
        node.join()


def record_edge_finals(rec: RecordSink, nodes: LimbNodes, lockstep: bool) -> None:
    """Each limb's final edge stats on `/stats` (they carry its `node_id`; in lockstep at its sample time) and as metadata
    (`sea-hil.edge` for the first limb, the 1-limb name; `sea-hil.edge.<limb>` for the others)."""
    for i, (limb, edge) in enumerate(zip(nodes.limbs, nodes.edges, strict=True)):
        now_ns = edge.core.sample_t_ns if lockstep else time.time_ns()
        rec.record("/stats", now_ns, now_ns, edge.stats_record(final=True))   # carries the limb's `node_id`
        rec.add_metadata("sea-hil.edge" if i == 0 else f"sea-hil.edge.{limb.name}",
                         {k: str(v) for k, v in edge.stats_dict().items()})


class ControllerGroup:
    """Several controller child processes waited for as one (`wait`, `returncode`: the first failure, else 0)."""

    def __init__(self, procs: list[subprocess.Popen]) -> None:
        self.procs = procs

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        for p in self.procs:
            p.wait(timeout=None if deadline is None else max(deadline - time.monotonic(), 0.0))
        code = self.returncode
        assert code is not None   # every child has ended
        return code

    @property
    def returncode(self) -> int | None:
        codes = [p.returncode for p in self.procs]
        if any(c is None for c in codes):
            return None
        return next((c for c in codes if c != 0), 0)


def controller_configs(cfg: SeaHilConfig, limbs: tuple[Limb, ...]) -> list[tuple[str, SeaHilConfig]]:
    """(file stem, config) of each limb's controller child: `controller` for one limb (the 1-limb name),
    `controller_<limb>` otherwise."""
    if len(limbs) == 1:
        return [("controller", limb_config(cfg, limbs[0]))]
    return [(f"controller_{limb.name}", limb_config(cfg, limb)) for limb in limbs]
