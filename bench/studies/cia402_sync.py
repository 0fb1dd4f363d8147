"""CPU per SYNC of the cia402 profile's 1 kHz path, deterministic (no bus, no threads, no clock waits): the drive's
side (`Cia402PlantNode.handle` of the SYNC and the two RPDO 3 frames, `tick`: integration, the CiA 301/402 nodes,
their TPDOs) and the master's (`Cia402EdgeNode`'s CANopen part: `Cia402Master.receive` of the four TPDOs,
`measurement`, `command`), each frame crossing as a python-can `Message` the way the shells hand them over. The
edge core's inner loop and Zenoh side are the sea profile's and not counted here.

    .venv/bin/python -m bench.studies.cia402_sync [--syncs 5000] [--profile]

prints CPU us per SYNC (process time, best of 3 rounds) for each side and, with `--profile`, cProfile's top
functions by own time. The frames on the bus are hashed (sha256 over id and data): the figure a change must keep
(bit for bit the same traffic)."""
from __future__ import annotations

import argparse
import cProfile
import hashlib
import pstats
import time
from collections.abc import Callable

import can

from sea_hil.config.loader import load_config
from sea_hil.controller.cia402_master import Cia402Master
from sea_hil.controller.cia402_master import Frame as MasterFrame
from sea_hil.plant_emulator.cia402_node import Cia402PlantNode

VOLTS = ((1.5, -0.8), (-0.4, 0.6))


class _Bus:
    """The drive node's bus: what it sends is collected (as python-can messages, like a real send)."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return None     # the frames reach the node through `handle`, as the shell hands them over


def _message(f: MasterFrame) -> can.Message:
    return can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=False)


def session(syncs: int) -> tuple[Callable[[], None], Callable[[], None], Callable[[], str]]:
    """(the set-up, one SYNC period, the traffic digest) of a lockstep drive node and master."""
    cfg = load_config(overrides={"can": {"profile": "cia402"}})
    bus = _Bus()
    plant = Cia402PlantNode(cfg, bus, lockstep=True)
    hip, knee = cfg.can.cia402.node_ids[:2]
    master = Cia402Master((hip, knee))
    digest = hashlib.sha256()
    k = [0]

    def deliver(frames: list[MasterFrame]) -> None:
        pending = list(frames)
        while pending:
            msg = _message(pending.pop(0))
            digest.update(msg.arbitration_id.to_bytes(2, "little") + bytes(msg.data))
            bus.sent.clear()
            plant.handle(msg)
            plant.tick()
            answers = list(bus.sent)
            for a in answers:
                digest.update(a.arbitration_id.to_bytes(2, "little") + bytes(a.data))
                pending += master.receive(MasterFrame(a.arbitration_id, bytes(a.data)))

    def setup() -> None:
        plant._on_start(None)
        bus.sent.clear()
        deliver(master.start())
        assert master.phase == "run", master.phase

    def one_sync() -> None:
        deliver(master.sync())
        m = master.measurement()
        assert m is not None
        k[0] += 1
        deliver(master.command(VOLTS[k[0] // 500 % 2]))

    return setup, one_sync, lambda: digest.hexdigest()


def measure(syncs: int) -> tuple[float, str]:
    setup, one_sync, digest = session(syncs)
    setup()
    t0 = time.process_time()
    for _ in range(syncs):
        one_sync()
    return (time.process_time() - t0) / syncs * 1e6, digest()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--syncs", type=int, default=5000)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    runs = [measure(args.syncs) for _ in range(3)]
    assert len({d for _, d in runs}) == 1
    print(f"{args.syncs} SYNCs: {min(us for us, _ in runs):.1f} us CPU per SYNC (drive + master, best of 3), "
          f"traffic sha256 {runs[0][1][:16]}")
    if args.profile:
        setup, one_sync, _ = session(args.syncs)
        setup()
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(args.syncs):
            one_sync()
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
