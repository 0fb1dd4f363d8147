"""The numba fast path of the offline closed loop is the plain-Python reference, compiled: same results, same
disturbance sampling, every callee compiled from its own source, a cache key that follows the callees' sources."""
from __future__ import annotations

import numpy as np
import pytest

from sea_hil import jit
from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.dynamics import initial_state
from sea_hil.errors import SeaHilError
from sea_hil.mechanics import limb_params
from sea_hil.offline.closed_loop import simulate
from sea_hil.offline.drive_kernel import make_session_steps
from sea_hil.plant_emulator.disturbance import DisturbanceTable, make_disturbance
from sea_hil.plant_emulator.integrator import advance

pytest.importorskip("numba")

NOISE = {"disturbance": {"kind": "noise", "amplitude_nm": [2.0, 1.0], "noise_hold_s": 0.0005}}
SHARP = {"controller": {"boundary_layer": 0.0, "cross_term_scale": "off"}, "sim": {"substeps": 3}}


def _cfg(overrides: dict) -> SeaHilConfig:
    return load_config(overrides={**overrides, "trajectory": {"kind": "gait", "period_s": 3.0}})


@pytest.mark.parametrize(("overrides", "mode"), [({}, "et"), (NOISE, "tt"), (SHARP, "et")])
def test_compiled_kernel_reproduces_the_plain_python_path(overrides: dict, mode: str) -> None:
    cfg = _cfg(overrides)
    fast, ref = simulate(cfg, mode, jit=True), simulate(cfg, mode, jit=False)
    np.testing.assert_array_equal(fast.event_t_s, ref.event_t_s)
    np.testing.assert_array_equal(fast.event_reason, ref.event_reason)
    assert fast.saturated_steps == ref.saturated_steps
    np.testing.assert_array_equal(fast.t_s, ref.t_s)
    np.testing.assert_allclose(fast.theta_rad, ref.theta_rad, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.max_abs_voltage_v, ref.max_abs_voltage_v, rtol=0, atol=1e-6)
    assert len(ref.event_t_s) > 10 and max(ref.max_abs_voltage_v) > 0.1  # the runs did something


@pytest.mark.parametrize("use_jit", [True, False])
def test_divergence_is_a_seahil_error_on_both_paths(use_jit: bool) -> None:
    cfg = _cfg({"can": {"feedback_rate_hz": 20.0}, "controller": {"sample_period_s": 0.05}, "sim": {"substeps": 1}})
    with pytest.raises(SeaHilError, match="diverged at t = 0.200 s"):
        simulate(cfg, "et", jit=use_jit)


def test_disturbance_table_holds_exactly_what_advance_samples() -> None:
    cfg = load_config(overrides=NOISE)
    p, dist = limb_params(cfg.plant), make_disturbance(cfg.disturbance)
    period_ns, substeps, n = 1_000_000, 3, 7
    seen: list[tuple[float, float]] = []

    def recording(t: float) -> tuple[float, float]:
        seen.append(dist(t))
        return seen[-1]

    x = initial_state(0.1, 0.3, 0.0, 0.0, p)
    for k in range(n):
        x = advance(k * period_ns * 1e-9, x, (1.0, -1.0), period_ns * 1e-9, substeps, p, recording)   # as DriverCore
    table = DisturbanceTable(cfg.disturbance, period_ns, substeps).upto(n)[:n * substeps]
    assert table.shape == (n * substeps, 6)
    np.testing.assert_array_equal(table.reshape(-1, 2), np.array(seen))
    assert len({tuple(r) for r in table.reshape(-1, 2)}) > 3  # held noise changes within the window


def test_no_disturbance_table_is_zero() -> None:
    cfg = load_config()
    assert not DisturbanceTable(cfg.disturbance, 1_000_000, 2).upto(5).any()


def test_the_table_grows_in_sample_order() -> None:
    cfg = load_config(overrides=NOISE)
    grown = DisturbanceTable(cfg.disturbance, 1_000_000, 2)
    grown.upto(3)
    whole = DisturbanceTable(cfg.disturbance, 1_000_000, 2).upto(3 * DisturbanceTable.CHUNK)
    np.testing.assert_array_equal(grown.upto(2 * DisturbanceTable.CHUNK), whole[:len(grown.rows)])


def test_every_callee_of_the_kernel_is_found() -> None:
    names = {f.__name__ for f in jit.project_callees(make_session_steps())}
    assert {"deflections", "limited_voltage", "backstepping_voltage", "_g_dot", "fx_gx", "rk4_core", "f",
            "sea_geometry", "apex_angles", "mass_matrix", "n_terms", "solve_m", "is_finite", "_sat"} <= names
    assert "advance" not in names and "sqrt" not in names


def test_the_cache_key_carries_the_callees_source_fingerprint() -> None:
    callees = jit.project_callees(make_session_steps())
    fp = jit.source_fingerprint([make_session_steps, *callees])
    assert len(fp) == 64 and fp == jit.source_fingerprint([*reversed(callees), make_session_steps])
    assert fp != jit.source_fingerprint([make_session_steps])
    kernel = jit.compiled(make_session_steps)
    assert [c.cell_contents for c in kernel.py_func.__closure__] == [fp]


def test_without_numba_there_is_no_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jit.importlib.util, "find_spec", lambda name: None)
    assert jit.compiled.__wrapped__(make_session_steps) is None
