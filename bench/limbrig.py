"""A real-time rig of N limbs in one process, composed by the same `SessionBuilder` as `sea-hil run`: one `PlantNode`
serving node ids 1..N on one python-can `virtual` bus (the batched driver: one schedule for all limbs), and one edge
core (`EdgeNode`, inner loop at the feedback rate) per limb on its own Zenoh limb key. Layouts (`layout`):
`threads` -- each core is a node with its own thread and bus handle (issue 17's baseline); `mux` -- one `EdgeMux`
reads the bus once and serves every core in its thread (one edge per bus, as `sea-hil run` composes a shared bus). The remote side is a setpoint echo child process (this file with
`--feeder ENDPOINT`) that answers every state of every limb with a setpoint holding the measured spring deflection
(so each edge keeps commanding; 100 setpoints/s per limb, the TT worst case). No recorder runs.

The first `warmup_s` (Zenoh connection, first setpoint, frames queued meanwhile) are run but not counted.
Closed-loop latency: the edges' `latency` histogram (state published -> setpoint arrived, wall clock).
Edge timing comes from the edge's own loop-time histogram (`EdgeCore.counters.loop`, `loop_overruns`): response =
VOLTAGE_CMD sent minus the bus timestamp of the feedback frame that completed the sample (on the `virtual` bus: the
driver's send time) -- bus queueing + wake-up + decode + inner loop + encode + send.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass
from typing import Any

import zenoh

from bench.benchlib import REPO, stop_process, wait_ready
from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.edge_mux import EdgeMux
from sea_hil.plant_emulator.node import PlantNode, TickStats
from sea_hil.protocol.payloads import PayloadCounters, SetpointPayload, StatePayload, TriggerReason, encode
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session, publisher
from sea_hil.session.builder import SessionBuilder
from sea_hil.stats.histogram import LogHistogram

PREFIX = "sea"


def feeder(endpoint: str) -> int:
    """Child: answer every `sea/*/state` with a setpoint holding the measured deflection, until terminated."""
    session = open_session(make_config(connect=[endpoint]))
    sub = session.declare_subscriber(f"{PREFIX}/*/state", zenoh.handlers.FifoChannel(4096))
    pubs: dict[str, zenoh.Publisher] = {}
    counters, seq = PayloadCounters(), 0
    print("ready", flush=True)
    while True:
        sample = sub.recv()
        p = counters.try_decode(sample.payload.to_bytes())
        if not isinstance(p, StatePayload):
            continue
        limb = str(sample.key_expr).split("/")[-2]
        pub = pubs.get(limb) or pubs.setdefault(limb, publisher(session, f"{PREFIX}/{limb}/setpoint"))
        seq += 1
        pub.put(encode(SetpointPayload(seq, time.monotonic_ns(), p.seq, p.delta_m, (0.0, 0.0),
                                       TriggerReason.TIME)))


@dataclass
class RigResult:
    limbs: int
    wall_s: float
    cpu_s: float
    ticks: int
    overruns: int
    lateness_p50_us: float
    lateness_p99_us: float
    lateness_max_us: float
    edge_samples: int
    edge_commands: int
    edge_late: int
    edge_p50_us: float
    edge_p99_us: float
    edge_max_us: float
    latency_p50_us: float = -1.0
    latency_p99_us: float = -1.0
    layout: str = "threads"

    @property
    def driver_miss_rate(self) -> float:
        return self.overruns / max(self.ticks + self.overruns, 1)

    @property
    def edge_miss_rate(self) -> float:
        """Late responses (> 1 period) plus unanswered samples, over samples."""
        unanswered = max(self.edge_samples - self.edge_commands, 0)
        return (self.edge_late + unanswered) / max(self.edge_samples, 1)

    def as_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d.update(driver_miss_rate=self.driver_miss_rate, edge_miss_rate=self.edge_miss_rate,
                 cpu_pct=100.0 * self.cpu_s / max(self.wall_s, 1e-9))
        return d


def _limb_cfg(cfg: SeaHilConfig, n: int) -> SeaHilConfig:
    return cfg.model_copy(update={"zenoh": cfg.zenoh.model_copy(update={"prefix": PREFIX, "limb": f"limb{n}"})})


def _reset(plant: PlantNode, edges: list[EdgeNode]) -> tuple[int, int]:
    """Forget the warm-up: fresh plant timing statistics and edge loop-time histograms; returns the edges'
    (feedback, commands) counts so far, to be subtracted."""
    plant.lateness, plant.stats = LogHistogram(), TickStats()
    for e in edges:
        e.core.counters.loop, e.core.counters.loop_overruns, e.core.counters.latency = LogHistogram(), 0, LogHistogram()
    return sum(e.core.counters.feedback for e in edges), sum(e.core.counters.commands_sent for e in edges)


def _us(h: LogHistogram, q: float) -> float:
    return h.percentile(q) * 1e6 if h.count else -1.0


def run_rig(limbs: int, duration_s: float, rate_hz: float = 1000.0, warmup_s: float = 1.0,
            layout: str = "threads") -> RigResult:
    """Run `limbs` limbs in real time for `warmup_s` (not counted) + `duration_s` of wall time; timing statistics."""
    if layout not in ("threads", "mux"):
        raise ValueError(f"layout must be 'threads' or 'mux', got {layout!r}")
    cfg = load_config(overrides={"can": {"feedback_rate_hz": rate_hz}})
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    channel = f"virtual:bench-rig-{uuid.uuid4().hex}"
    ids = tuple(range(1, limbs + 1))
    warm = (0, 0)
    with SessionBuilder(cfg) as b:
        session = b.zenoh(listen=[endpoint], connect=())
        proc = subprocess.Popen([sys.executable, "-m", "bench.limbrig", "--feeder", endpoint], cwd=REPO,
                                stdout=subprocess.PIPE)
        b.callback(stop_process, proc)
        plant_bus = b.bus(channel)
        buses = [b.bus(channel) for _ in ids] if layout == "threads" else [b.bus(channel)] * limbs
        wait_ready(proc)
        plant = b.plant(plant_bus, ids)
        edges: list[EdgeNode] = [b.edge(bus, session, n, cfg=_limb_cfg(cfg, n)) for n, bus in zip(ids, buses, strict=True)]
        for runner in edges if layout == "threads" else [b.add(EdgeMux(buses[0], edges))]:
            runner.start()
        if warmup_s > 0:    # start-up (connections, first setpoint, queued frames) is not steady-state timing
            plant.run(warmup_s)
            warm = _reset(plant, edges)
        cpu0, t0 = time.process_time(), time.monotonic()
        plant.run(duration_s)   # the schedule restarts from now; driver state carries on
        wall_s, cpu_s = time.monotonic() - t0, time.process_time() - cpu0
    resp, closed = LogHistogram(), LogHistogram()
    for e in edges:
        resp.merge(e.core.counters.loop)
        closed.merge(e.core.counters.latency)
    lat = plant.lateness
    late = sum(e.core.counters.loop_overruns for e in edges)
    return RigResult(limbs, wall_s, cpu_s, plant.stats.ticks, plant.stats.overruns, lat.percentile(50) * 1e6,
                     lat.percentile(99) * 1e6, lat.max * 1e6, sum(e.core.counters.feedback for e in edges) - warm[0],
                     sum(e.core.counters.commands_sent for e in edges) - warm[1], late, _us(resp, 50), _us(resp, 99),
                     resp.max * 1e6 if resp.count else -1.0, _us(closed, 50), _us(closed, 99), layout)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="setpoint feeder child of the limb rig")
    ap.add_argument("--feeder", metavar="ENDPOINT", required=True)
    sys.exit(feeder(ap.parse_args().feeder))
