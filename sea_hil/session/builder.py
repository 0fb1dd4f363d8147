"""The one session builder: every composition of nodes (the `sea-hil plant|edge|controller|record|run` commands,
the benchmark rig, the tests) goes through `SessionBuilder`.

It opens CAN buses and Zenoh sessions from the frozen config, builds nodes that share one clock (`lockstep` picks
the lockstep clock, `sea_hil.runtime`), and owns every resource it made in an `ExitStack`: `close()` (or leaving
the `with` block) stops and closes the nodes, then the sessions and buses, in reverse order of creation, once.
`serve(node)` is the lifecycle of a node run on its own: SIGTERM stops it, it runs, its final stats record
is published. A later public API (`Session(...)`, `EmulatedDriver(...)`) wraps these calls.
"""
from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterable
from contextlib import ExitStack
from typing import Any, TypeVar

import can
import zenoh
from zenoh import Session as ZenohSession  # `zenoh` in the class body is the method

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.cia402_edge import Cia402EdgeNode
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.remote import RemoteController
from sea_hil.plant_emulator.cia402_node import Cia402PlantNode
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.bus_timing import warn_if_overloaded
from sea_hil.protocol.canbus import CanHandle, open_bus
from sea_hil.protocol.timed_bus import TimedBus, make_timeline
from sea_hil.protocol.zsession import open_session
from sea_hil.recorder.node import RecorderNode
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.runtime.lockstep import clock_for
from sea_hil.runtime.node import Node

N = TypeVar("N", bound=Node)


class SessionBuilder:
    def __init__(self, cfg: SeaHilConfig, *, lockstep: bool = False) -> None:
        self.cfg = cfg
        self.lockstep = lockstep
        self.clock = clock_for(lockstep)
        self._stack = ExitStack()
        self.timelines: dict[str, Any] = {}
        self._load_checked: set[str] = set()

    # ---- resources ------------------------------------------------------------------------------------------------
    def zenoh(self, *, listen: Iterable[str] | None = None, connect: Iterable[str] | None = None,
              mode: str | None = None) -> zenoh.Session:
        """A Zenoh session from `cfg.zenoh` (mode, TLS, ACL), its endpoints (and mode) replaced where given."""
        z = self.cfg.zenoh
        update: dict[str, Any] = {k: tuple(v) for k, v in (("listen", listen), ("connect", connect)) if v is not None}
        if mode is not None:
            update["mode"] = mode
        if update:
            z = z.model_validate({**z.model_dump(), **update})
        session = open_session(z)
        self._stack.callback(session.close)
        return session

    def bus(self, spec: str | None = None) -> can.BusABC:
        """A CAN bus handle (`spec`, default `cfg.can.interface`; the `[can] fd` profile), shut down on close. The
        first handle of a bus warns when its planned load is too high; with `[can] emulate_bitrate` every handle of
        a bus goes through that bus's one timing model (`sea_hil.protocol.timed_bus`)."""
        spec, cc = spec or self.cfg.can.interface, self.cfg.can
        if spec not in self.timelines and spec not in self._load_checked:
            self._load_checked.add(spec)
            warn_if_overloaded(cc, cc.node_ids, spec)
        bus: Any = open_bus(spec, fd=cc.fd)
        if cc.emulate_bitrate:
            if spec not in self.timelines:
                self.timelines[spec] = make_timeline(cc, spec, self.lockstep)
            bus = TimedBus(bus, self.timelines[spec])
        self._stack.callback(bus.shutdown)
        return bus

    def bus_timing(self) -> dict[str, Any]:
        """Per bus (spec): the timing model's frames, load and per-id queueing delay and latency (`BusArbiter.stats`);
        empty without `[can] emulate_bitrate`."""
        return {spec: t.arbiter.stats() for spec, t in self.timelines.items()}

    def callback(self, fn: Callable[..., Any], *args: Any) -> None:
        """Run `fn(*args)` on close (after everything added later, before everything added earlier)."""
        self._stack.callback(fn, *args)

    def add(self, node: N) -> N:
        """Own `node`: it is closed (stopped, joined, released) on close."""
        self._stack.callback(node.close)
        return node

    # ---- nodes ----------------------------------------------------------------------------------------------------
    def plant(self, bus: CanHandle, node_ids: tuple[int, ...], cfg: SeaHilConfig | None = None) -> Any:
        cfg = cfg or self.cfg
        if cfg.can.profile == "cia402":   # the CANopen nodes of [can.cia402] node_ids (docs/cia402.md)
            return self.add(Cia402PlantNode(cfg, bus, cfg.can.cia402.node_ids, lockstep=self.lockstep))
        return self.add(PlantNode(cfg, bus, node_ids, clock=self.clock))

    def edge(self, bus: CanHandle, session: ZenohSession, node_id: int, *, inner: str = "edge",
             cfg: SeaHilConfig | None = None, mode: str = "et") -> Any:
        """`mode` (et | tt) is the trigger the edge runs when `trigger.placement = "edge"`."""
        cfg = cfg or self.cfg
        if cfg.can.profile == "cia402":   # the edge as the CANopen master of the limb's two nodes
            ids = cfg.can.cia402.node_ids
            return self.add(Cia402EdgeNode(cfg, bus, session, (ids[0], ids[1]), inner=inner, clock=self.clock,
                                           mode=mode))
        return self.add(EdgeNode(cfg, bus, session, node_id, inner=inner, clock=self.clock, mode=mode))

    def controller(self, session: ZenohSession, mode: str, *, inner: str = "edge", cycles: int = 1) -> Any:
        return self.add(RemoteController(self.cfg, session, mode, inner=inner, clock=self.clock, cycles=cycles))

    def recorder(self, rec: SessionRecorder | RecorderProcess, session: ZenohSession | None,
                 bus: can.BusABC | None = None,
                 **kw: Any) -> Any:
        if isinstance(bus, TimedBus):
            bus.listen_only = True   # the bus-timing model does not wait for a recorder (it never answers)
        node = self.add(RecorderNode(rec, session, self.cfg.zenoh.prefix, bus, **kw))
        if self.cfg.can.profile == "cia402":   # its in-process tap decodes CANopen (a recorder process: by config.toml)
            node.tap.configure(config_to_toml(self.cfg))
        return node

    # ---- lifecycle ------------------------------------------------------------------------------------------------
    def serve(self, node: Node, duration_s: float | None = None,
              signals: tuple[signal.Signals, ...] = (signal.SIGTERM,)) -> bool:
        """Run `node` in this thread until it finishes, `duration_s` passes or one of `signals` stops it; then publish
        its final stats record. The node's result (`Node.run`)."""
        restore = _stop_on_signals(node, signals)
        try:
            return node.run(duration_s)
        finally:
            restore()
            node.publish_stats(final=True)

    def close(self) -> None:
        self._stack.close()

    def __enter__(self) -> SessionBuilder:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def _stop_on_signals(node: Node, signals: tuple[signal.Signals, ...]) -> Callable[[], None]:
    """`signals` stop `node` (main thread only); returns a function restoring the old handlers. The first signal
    stops it, later ones do nothing: a handler runs between two bytecodes of the main thread, so a second SIGTERM
    arriving while the first handler's `Event.set` holds the event's lock would wait for that lock forever (seen:
    a `sea-hil plant` driver child, SIGTERMed more than once when its session was SIGKILLed, hung in nested
    handlers)."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    fired: list[int] = []

    def handler(signum: int, _frame: object) -> None:
        if not fired:
            fired.append(signum)
            node.stop()
    old = {sig: signal.signal(sig, handler) for sig in signals}

    def restore() -> None:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return restore
