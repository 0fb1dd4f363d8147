"""Real-time timing of the emulated SEA driver node: `PlantNode` at 1 kHz over a python-can `virtual` bus with a
responder thread answering every feedback with a VoltageCmd (like the edge would).

Run: python bench/bench_driver_timing.py [--seconds 10] [--rate 1000] [--load]
Prints one markdown table row per configuration: ticks, overruns, overrun rate, tick lateness p50/p99/max (us),
commands the driver took and watchdog trips. `--load` adds a run with a busy-loop process keeping another core busy
(ended afterwards).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import threading
import uuid
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # runnable from a source checkout

import can  # noqa: E402

from plant_emulator.node import PlantNode  # noqa: E402
from protocol.can_codec import FeedbackAngle, SeaCodec, VoltageCmd  # noqa: E402
from protocol.canbus import open_bus  # noqa: E402
from protocol.config import load_config  # noqa: E402

NODE = 1
HEADER = ("| config | ticks | overruns | overrun rate | lateness p50 (us) | p99 (us) | max (us) | commands | "
          "watchdog trips |\n|---|---|---|---|---|---|---|---|---|")


@dataclass(frozen=True)
class Result:
    ticks: int
    overruns: int
    p50_us: float
    p99_us: float
    max_us: float
    commands: int
    watchdog_trips: int

    def row(self, name: str) -> str:
        rate = self.overruns / max(self.ticks + self.overruns, 1)
        return (f"| {name} | {self.ticks} | {self.overruns} | {rate:.2%} | {self.p50_us:.0f} | {self.p99_us:.0f} | "
                f"{self.max_us:.0f} | {self.commands} | {self.watchdog_trips} |")


def respond(bus: can.BusABC, stop: threading.Event, voltage_v: tuple[float, float]) -> None:
    """Answer each FEEDBACK_ANGLE frame with a VoltageCmd of the same seq until `stop` is set."""
    codec = SeaCodec([NODE])
    while not stop.is_set():
        msg = bus.recv(timeout=0.05)
        if msg is None:
            continue
        frame = codec.decode(msg)
        if isinstance(frame, FeedbackAngle):
            bus.send(codec.encode(VoltageCmd(NODE, voltage_v, frame.seq)))


def measure(seconds: float, rate_hz: float) -> Result:
    """Run the node for `seconds` of wall time with a responder and return its timing statistics."""
    cfg = load_config(overrides={"can": {"feedback_rate_hz": rate_hz}})
    channel = f"virtual:bench-driver-{uuid.uuid4().hex}"
    node_bus, peer_bus = open_bus(channel), open_bus(channel)
    node = PlantNode(cfg, node_bus, (NODE,))
    stop = threading.Event()
    responder = threading.Thread(target=respond, args=(peer_bus, stop, (0.5, 0.0)), daemon=True)
    responder.start()
    try:
        node.run(seconds)
    finally:
        stop.set()
        responder.join(timeout=5.0)
        node_bus.shutdown()
        peer_bus.shutdown()
    drv, lat = node.drivers[NODE], node.lateness
    return Result(node.stats.ticks, node.stats.overruns, lat.percentile(50) * 1e6, lat.percentile(99) * 1e6,
                  lat.max * 1e6, drv.counters.commands, drv.counters.watchdog_trips)


def measure_loaded(seconds: float, rate_hz: float) -> Result:
    """`measure` while a busy-loop process occupies a core; the process is ended afterwards."""
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        return measure(seconds, rate_hz)
    finally:
        hog.kill()
        hog.wait(timeout=10.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="wall time per configuration (default 10)")
    ap.add_argument("--rate", type=float, default=1000.0, help="feedback rate in Hz (default 1000)")
    ap.add_argument("--load", action="store_true", help="also run with a busy-loop process on another core")
    args = ap.parse_args(argv)
    print(HEADER)
    print(measure(args.seconds, args.rate).row(f"idle, {args.rate:g} Hz"), flush=True)
    if args.load:
        print(measure_loaded(args.seconds, args.rate).row(f"1 busy core, {args.rate:g} Hz"), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
