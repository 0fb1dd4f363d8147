"""CPU cost of the batched driver's two hot parts (issue 17): frame plans against cantools, and the batch step
against one `advance` per limb. CPU time (thread_time, best of 7 repeats), so it is less load-sensitive than wall time;
still, measure on a quiet machine for final figures.

Run: python -m bench.studies.bench_batched [--limbs 1,2,4,8]
Prints, per hot message: cantools strict `encode` / `decode` vs the plan's generated pack / unpack (us per frame);
the codec's cost per limb-sample (feedback encode + decode, voltage encode + decode; classic and CAN FD); and the
driver's integration of one period for N limbs: N `DriverCore.step` calls vs one `step_all` (us per limb-sample).
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from functools import partial

import can
from cantools.database.can.signal import Signal

from sea_hil.config.loader import load_config
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.batch import prepare_batch, step_all
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import prepare_advance
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import Feedback, VoltageCmd
from sea_hil.protocol.frame_plan import FramePlan

HOT = ("VOLTAGE_CMD", "FEEDBACK_ANGLE", "FEEDBACK_JOINT1", "FEEDBACK_JOINT2", "VOLTAGE_CMD_FD", "FEEDBACK_FD",
       "HEARTBEAT")


def cpu_us(fn: Callable[[], object], n: int = 2000) -> float:
    best = float("inf")
    for _ in range(7):
        t0 = time.thread_time_ns()
        for _ in range(n):
            fn()
        best = min(best, (time.thread_time_ns() - t0) / n / 1e3)
    return best


def _mid(sig: Signal) -> float:
    """A value inside the signal's range: the middle of a scaled signal, half the maximum of a raw one."""
    lo, hi = sig.minimum, sig.maximum
    assert lo is not None and hi is not None, f"{sig.name}: the DBC gives every hot signal a range"
    return (lo + hi) / 2 if sig.conversion.scale != 1 else int(hi) // 2


def _decode_all(codec: SeaCodec, msgs: Sequence[can.Message]) -> list[object]:
    return [codec.decode(x) for x in msgs]


def _step_each(cores: list[DriverCore]) -> list[object]:
    return [d.step() for d in cores]


def messages() -> None:
    db = load_database()
    for name in HOT:
        msg = db.get_message_by_name(name)
        plan = FramePlan.of(msg)
        row = {s.name: _mid(s) for s in msg.signals}
        values = tuple(row[n] for n in plan.names)
        data = msg.encode(row, strict=True)
        print(f"  {name:16s} encode cantools {cpu_us(partial(msg.encode, row, strict=True)):5.1f} / plan "
              f"{cpu_us(partial(plan.pack_plain, values)):4.1f} us; decode cantools "
              f"{cpu_us(partial(msg.decode, data, decode_choices=False, allow_excess=False)):5.1f} / plan "
              f"{cpu_us(partial(plan.unpack_plain, data)):4.1f} us")


def codec_per_limb_sample() -> None:
    fb = Feedback(1, 5, 1234, (0.1, -0.2), (1.0, -2.0), (0.001, -0.002), (0.01, -0.02))
    v = VoltageCmd(1, (1.5, -2.5), 5)
    for fd in (False, True):
        c = SeaCodec([1], fd=fd)
        msgs, m = c.encode_feedback(fb, saturate=True), c.encode(v)
        parts = {"feedback encode": cpu_us(partial(c.encode_feedback, fb, saturate=True)),
                 "feedback decode": cpu_us(partial(_decode_all, c, msgs)),
                 "voltage encode": cpu_us(partial(c.encode, v, saturate=True)),
                 "voltage decode": cpu_us(partial(c.decode, m))}
        print(f"  {'CAN FD' if fd else 'classic':7s}: " + ", ".join(f"{k} {x:.1f}" for k, x in parts.items())
              + f" -> {sum(parts.values()):.1f} us CPU per limb-sample")


def step_per_limb_sample(limbs: list[int]) -> None:
    cfg = load_config()
    p = limb_params(cfg.plant)
    prepare_advance(p)
    prepare_batch(p)
    for n in limbs:
        hip, knee = cfg.plant.initial_theta_rad
        cores = [DriverCore.create(i + 1, p, 1e-3, 0.1, cfg.sim.substeps, (hip, knee), lambda t: (0.0, 0.0))
                 for i in range(n)]
        alone = cpu_us(partial(_step_each, cores), 500) / n
        batched = cpu_us(partial(step_all, cores), 500) / n
        print(f"  {n} limbs: {alone:5.1f} us per limb-sample one step per limb, {batched:5.1f} us batched "
              f"({alone / batched:.2f}x)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", default="1,2,4,8")
    args = ap.parse_args(argv)
    print("frame plans vs cantools (us CPU per frame):")
    messages()
    print("codec per limb-sample:")
    codec_per_limb_sample()
    print("driver integration of one period (compiled kernels loaded):")
    step_per_limb_sample([int(x) for x in args.limbs.split(",")])
    return 0


if __name__ == "__main__":
    sys.exit(main())
