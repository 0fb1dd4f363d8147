"""Test rig of the CiA 402 profile: the emulated drive (`Cia402PlantNode`, in its thread) and python canopen's
master (`BaseNode402` per SEA, from the shipped EDS files) on one bus, the drive on a clock the rig advances itself
(`ManualClock`; real time when `manual=False`). Every wait is for a frame (queues filled by canopen callbacks, with a
timeout), never a sleep."""
from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import can
import canopen
from canopen.profiles.p402 import BaseNode402

from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.plant_emulator.cia402_node import Cia402PlantNode
from sea_hil.protocol.cia402_eds import eds_path

TIMEOUT_S = 5.0


@dataclass
class ManualClock:
    t_ns: int = 0

    def __call__(self) -> int:
        return self.t_ns


def cia402_config(**can: Any) -> SeaHilConfig:
    return load_config(overrides={"can": {"profile": "cia402", **can}})


@dataclass
class Rig:
    cfg: SeaHilConfig
    interface: str
    channel: str
    manual: bool = True
    clock: ManualClock = field(default_factory=ManualClock)
    frames: queue.Queue[tuple[int, bytes]] = field(default_factory=queue.Queue)

    def __post_init__(self) -> None:
        self.drive_bus = can.Bus(interface=self.interface, channel=self.channel, receive_own_messages=False)
        self.drive = Cia402PlantNode(self.cfg, self.drive_bus, now_ns=self.clock if self.manual else time.monotonic_ns,
                                     jit=False)
        self.network = canopen.Network()
        self.network.connect(interface=self.interface, channel=self.channel)
        hip_id, knee_id = self.cfg.can.cia402.node_ids[:2]
        self.hip = BaseNode402(hip_id, str(eds_path("hip")))
        self.knee = BaseNode402(knee_id, str(eds_path("knee")))
        self.nodes = (self.hip, self.knee)
        for n in self.nodes:
            self.network.add_node(n)
            n.sdo.RESPONSE_TIMEOUT = TIMEOUT_S      # canopen's 0.3 s is short for a loaded test machine or guest
            for name in ("TIMEOUT_SWITCH_OP_MODE", "TIMEOUT_SWITCH_STATE_FINAL", "TIMEOUT_SWITCH_STATE_SINGLE",
                         "TIMEOUT_CHECK_TPDO"):
                setattr(n, name, TIMEOUT_S)         # bounds on a wait for a frame: only a failure waits this long
        self.pdo_queues: dict[tuple[int, int], queue.Queue[Any]] = {}
        self.emcys: queue.Queue[tuple[int, Any]] = queue.Queue()
        self.boot_ups: queue.Queue[int] = queue.Queue()
        for n in self.nodes:
            self.network.subscribe(0x700 + n.id, lambda can_id, data, ts: self.boot_ups.put(can_id - 0x700)
                                   if bytes(data) == b"\0" else None)
        for n in self.nodes:
            n.emcy.add_callback(lambda err, nid=n.id: self.emcys.put((nid, err)))
        self.drive.start()

    def close(self) -> None:
        self.network.disconnect()
        self.drive.close()
        self.drive_bus.shutdown()

    def boot(self) -> None:
        """Wait for both nodes' power-on boot-up (subscribed before the drive started: none missed), read their PDO
        configuration."""
        for n in self.nodes:
            self.wait_boot_up(n.id)
            n.setup_402_state_machine()

    def wait_boot_up(self, node_id: int) -> None:
        while self.boot_ups.get(timeout=TIMEOUT_S) != node_id:
            pass

    def watch_tpdos(self) -> None:
        """Queue every reception of the enabled TPDOs (after `pdo.read()` / `save()` subscribed them)."""
        for n in self.nodes:
            for number, tpdo in n.tpdo.items():
                q: queue.Queue[Any] = queue.Queue()
                self.pdo_queues[(n.id, number)] = q
                tpdo.add_callback(lambda m, q=q: q.put({v.index: v.raw for v in m}))

    def tpdo(self, node: BaseNode402, number: int) -> dict[int, int]:
        return self.pdo_queues[(node.id, number)].get(timeout=TIMEOUT_S)

    @contextlib.contextmanager
    def pumping(self, step_ns: int = 1_000_000) -> Iterator[None]:
        """While the body runs (a blocking canopen call that waits in wall-clock time), the drive's manual clock
        runs too: +`step_ns` per half millisecond of wall time, so its timers fire."""
        stop = threading.Event()

        def pump() -> None:
            while not stop.wait(0.0005):
                self.clock.t_ns += step_ns

        thread = threading.Thread(target=pump, name="clock-pump", daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join()

    def step_ms(self, ms: int = 1) -> None:
        self.clock.t_ns += ms * 1_000_000

    def cycle(self, torques: tuple[int, int] | None, tpdos: tuple[int, ...] = (2, 3)) -> list[dict[int, int]]:
        """One SYNC period: time +1 ms, SYNC, wait for both nodes' synchronous `tpdos`, then send the target
        torques (per mille) in RPDO 2 (they act at the next SYNC). -> per node the merged TPDO values."""
        self.step_ms()
        self.network.sync.transmit()
        out = []
        for n in self.nodes:
            values: dict[int, int] = {}
            for number in tpdos:
                values.update(self.tpdo(n, number))
            out.append(values)
        if torques is not None:
            for n, t in zip(self.nodes, torques, strict=True):
                n.rpdo[2]["Target torque"].raw = t
                n.rpdo[2].transmit()
        return out
