"""The batch integration step (`plant_emulator.batch`): N limbs of a bus in one compiled call equal, bit for bit, each
limb stepped alone (`DriverCore.step`, `advance`'s kernel), with voltage changes inside the period and a disturbance."""
from __future__ import annotations

import math
import random

import pytest

from sea_hil.config.loader import load_config
from sea_hil.jit import loaded
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.batch import make_batch_kernel, prepare_batch, step_all
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import make_advance_kernel, prepare_advance
from sea_hil.protocol.can_frames import VoltageCmd

PERIOD_NS = 1_000_000
LIMBS = 4


def _dist(t: float) -> tuple[float, float]:
    return (0.3 * math.sin(12.0 * t), -0.05 * math.cos(7.0 * t))


def _cores(theta0: list[tuple[float, float]]) -> list[DriverCore]:
    cfg = load_config()
    p = limb_params(cfg.plant)
    return [DriverCore.create(i + 1, p, PERIOD_NS * 1e-9, 0.1, cfg.sim.substeps, th, _dist)
            for i, th in enumerate(theta0)]


def _commands(rng: random.Random, periods: int) -> list[list[list[tuple[int, tuple[float, float]]]]]:
    """Per period, per limb: (arrival offset ns, voltage) of 0-2 commands inside the period."""
    return [[sorted((rng.randrange(0, PERIOD_NS), (rng.uniform(-8, 8), rng.uniform(-8, 8)))
                    for _ in range(rng.randrange(0, 3))) for _ in range(LIMBS)] for _ in range(periods)]


def _run(cores: list[DriverCore], plan, batch: bool) -> list:
    out = []
    for k, per_limb in enumerate(plan):
        start = k * PERIOD_NS
        for drv, cmds in zip(cores, per_limb, strict=True):
            drv.period_start_ns = start
            for offset, u in cmds:
                drv.handle(VoltageCmd(drv.node_id, u, drv.seq & 0xFF), start + offset)
        out.append(step_all(cores) if batch else [drv.step() for drv in cores])
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_batch_step_equals_each_limb_alone(seed: int) -> None:
    cfg = load_config()
    p = limb_params(cfg.plant)
    if not (prepare_advance(p) and prepare_batch(p)):
        pytest.skip("numba not installed: step_all runs DriverCore.step itself")
    assert loaded(make_batch_kernel) is not None and loaded(make_advance_kernel) is not None
    rng = random.Random(seed)
    theta0 = [(rng.uniform(-0.3, 0.3), rng.uniform(-0.6, 0.0)) for _ in range(LIMBS)]
    plan = _commands(rng, 60)
    alone, batched = _cores(theta0), _cores(theta0)
    want, got = _run(alone, plan, batch=False), _run(batched, plan, batch=True)
    assert got == want
    assert [d.x for d in batched] == [d.x for d in alone]
    assert len({d.x for d in batched}) == LIMBS    # the limbs really differ (no copy of one row)
