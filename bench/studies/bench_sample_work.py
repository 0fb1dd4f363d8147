"""CPU of one limb-sample's work on the driver's and the edge's CAN side, without threads or real time (issue 17).

Run: python -m bench.studies.bench_sample_work [--limbs 1] [--repeat 7] [--number 3000]
     (A/B: run it with each checkout's interpreter, alternating: /other/.venv/bin/python -m bench.studies.bench_sample_work)
One `PlantNode` on a `virtual` bus with two more handles on the channel (the edge's and the recorder tap's), as in
`sea-hil run`. Per part, thread CPU time (`time.thread_time`) per limb-sample, best of `--repeat` rounds of
`--number` samples (the least disturbed round; on a loaded machine the spread is printed too):
- driver tick: VOLTAGE_CMD handled (decode + `DriverCore.handle`), lateness recorded, watchdog, one period
  integrated for every limb (`step_drivers`), each limb's feedback encoded (3 classic frames) and sent in one batch;
- edge CAN side: the feedback frames decoded and assembled (`FeedbackAssembler`), the sample time unwrapped, the
  loop time recorded (`LogHistogram`), a VOLTAGE_CMD encoded and sent;
- recorder tap: each frame turned into a `RawFrame`.
The frames the other handles received are drained in the part that reads them. The session's own CPU per
limb-sample (threads, waits, Zenoh, controllers) is bench/bench_cpu_per_sample.py.
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

from sea_hil.config.loader import load_config
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_assembly import FeedbackAssembler, unwrap_us
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import FEEDBACK_PARTS, Feedback, VoltageCmd
from sea_hil.protocol.canbus import open_bus
from sea_hil.recorder.can_tap import RawFrame
from sea_hil.stats.histogram import LogHistogram


def parts(limbs: int) -> dict[str, Callable[[], None]]:
    cfg = load_config()
    ids = tuple(range(1, limbs + 1))
    channel = f"virtual:sample-work-{limbs}"
    bus, edge_bus, tap_bus = open_bus(channel), open_bus(channel), open_bus(channel)
    node = PlantNode(cfg, bus, ids)
    node.prepare_kernels()
    codec = SeaCodec.for_bus(cfg.can, ids)
    assembler, loop = FeedbackAssembler(), LogHistogram()
    cmds = [codec.encode(VoltageCmd(n, (0.5, -0.3), 0), saturate=True) for n in ids]
    state = {"t_us": 0}

    def driver() -> None:
        for m in cmds:
            node._on_message(m, time.monotonic_ns())
        node.lateness.record(1.3e-5)
        now = time.monotonic_ns()
        for drv in node.drivers.values():
            drv.check_watchdog(now)
        node.publish_samples(node.step_drivers())
        node.send_pending()

    def edge() -> None:
        while (msg := edge_bus.recv(0)) is not None:
            frame = codec.decode(msg)
            fb = (frame if isinstance(frame, Feedback)
                  else assembler.push(frame) if isinstance(frame, FEEDBACK_PARTS) else None)
            if fb is not None:
                state["t_us"] = unwrap_us(state["t_us"], fb.t_us)
                loop.record(2.1e-4)
                edge_bus.send(codec.encode(VoltageCmd(fb.node_id, (0.4, -0.2), fb.seq), saturate=True))

    def tap() -> None:
        while (msg := tap_bus.recv(0)) is not None:
            RawFrame.of(round(msg.timestamp * 1e9), msg)
        while bus.recv(0) is not None:   # the edge's VOLTAGE_CMDs reach the driver's queue too
            pass

    return {"driver tick": driver, "edge CAN side": edge, "recorder tap": tap}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--number", type=int, default=3000)
    args = ap.parse_args(argv)
    fns = parts(args.limbs)
    cpu: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(200):   # warm up (numba, caches)
        for fn in fns.values():
            fn()
    for _ in range(args.repeat):
        spent = dict.fromkeys(fns, 0.0)
        for _ in range(args.number):   # the parts in pipeline order, each sample
            for name, fn in fns.items():
                t0 = time.thread_time()
                fn()
                spent[name] += time.thread_time() - t0
        for name in fns:
            cpu[name].append(1e6 * spent[name] / (args.number * args.limbs))
    total = [sum(v) for v in zip(*cpu.values(), strict=True)]
    for name, v in [*cpu.items(), ("total", total)]:
        print(f"{name:16s} {min(v):7.1f} us per limb-sample (best of {args.repeat}; median {sorted(v)[len(v) // 2]:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
