"""Tests of plant_emulator/driver.py: the pure `DriverCore` state machine, driven with explicit times."""
from __future__ import annotations

import pytest

from sea_hil.config.loader import load_config
from sea_hil.dynamics import initial_state
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import advance
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import (
    ClearErrors,
    DeflectionSetpoint,
    DriverState,
    ErrorFlags,
    EStop,
    Heartbeat,
    VoltageCmd,
)

PERIOD_NS = 1_000_000
WATCHDOG_NS = 100_000_000
NODE = 1


def _no_dist(t: float) -> tuple[float, float]:
    return (0.0, 0.0)


def make_core(node_id: int = NODE) -> DriverCore:
    cfg = load_config()
    return DriverCore.create(node_id, limb_params(cfg.plant), PERIOD_NS * 1e-9, WATCHDOG_NS * 1e-9, cfg.sim.substeps,
                             tuple(cfg.plant.initial_theta_rad), _no_dist)


def cmd(v1: float, v2: float = 0.0, seq: int = 0) -> VoltageCmd:
    return VoltageCmd(NODE, (v1, v2), seq)


def test_boots_in_init_at_rest_with_zero_voltage() -> None:
    core = make_core()
    x0 = core.x
    assert core.state is DriverState.INIT and core.flags == ErrorFlags(0) and core.voltage_v == (0.0, 0.0)
    fb = core.step()
    assert fb.seq == 1 and fb.t_us == 1000
    assert fb.theta_rad == pytest.approx(x0[:2], abs=1e-9)  # equilibrium: zero voltage holds the limb


def test_first_voltage_command_starts_running() -> None:
    core = make_core()
    assert core.handle(cmd(2.0, -1.5), now_ns=5)
    assert core.state is DriverState.RUNNING and core.voltage_v == (2.0, -1.5)
    assert core.last_cmd_ns == 5 and core.counters.commands == 1


def test_watchdog_trips_after_timeout_not_before() -> None:
    core = make_core()
    t0 = 1_000_000_000
    core.handle(cmd(2.0), t0)
    core.check_watchdog(t0 + WATCHDOG_NS)            # exactly at the timeout: still fine
    assert core.state is DriverState.RUNNING and core.counters.watchdog_trips == 0
    core.check_watchdog(t0 + WATCHDOG_NS + 1)
    assert core.state is DriverState.FAULT and ErrorFlags.WATCHDOG in core.flags
    assert core.voltage_v == (0.0, 0.0) and core.counters.watchdog_trips == 1
    core.check_watchdog(t0 + 10 * WATCHDOG_NS)        # no double counting
    assert core.counters.watchdog_trips == 1


def test_fresh_commands_keep_the_watchdog_quiet() -> None:
    core = make_core()
    for k in range(50):
        t = k * (WATCHDOG_NS // 2)
        core.handle(cmd(1.0), t)
        core.check_watchdog(t + WATCHDOG_NS // 2)
    assert core.state is DriverState.RUNNING and core.counters.watchdog_trips == 0


def test_watchdog_does_not_run_in_init() -> None:
    core = make_core()
    core.check_watchdog(10 * WATCHDOG_NS)
    assert core.state is DriverState.INIT and core.flags == ErrorFlags(0)


def test_zero_voltage_in_fault_matches_unforced_model() -> None:
    core = make_core()
    core.handle(cmd(5.0, 5.0), 0)
    for _ in range(20):
        core.step()
    core.check_watchdog(WATCHDOG_NS + 1)
    assert core.state is DriverState.FAULT
    x, t_s = core.x, core.sample_t_ns * 1e-9
    expected = advance(t_s, x, (0.0, 0.0), PERIOD_NS * 1e-9, core.substeps, core.params, _no_dist)
    assert core.step().theta_rad == pytest.approx(expected[:2], abs=1e-12)


@pytest.mark.parametrize("latch", ["watchdog", "estop"])
def test_commands_ignored_in_fault_and_estop_and_only_clear_errors_leaves(latch: str) -> None:
    core = make_core()
    core.handle(cmd(3.0), 0)
    if latch == "watchdog":
        core.check_watchdog(WATCHDOG_NS + 1)
        latched, flag = DriverState.FAULT, ErrorFlags.WATCHDOG
    else:
        core.handle(EStop(NODE), 10)
        latched, flag = DriverState.ESTOP, ErrorFlags.ESTOP
    for k in range(5):
        assert core.handle(cmd(4.0, seq=k), WATCHDOG_NS + 10 + k)
        core.check_watchdog(10 * WATCHDOG_NS)
        core.step()
    assert not core.handle(DeflectionSetpoint(NODE, (0.001, 0.0), 0), WATCHDOG_NS)
    assert core.state is latched and flag in core.flags and core.voltage_v == (0.0, 0.0)
    assert core.counters.ignored_commands == 6 and core.counters.commands == 1
    assert core.handle(ClearErrors(NODE), 11 * WATCHDOG_NS)
    assert core.state is DriverState.INIT and core.flags == ErrorFlags(0) and core.voltage_v == (0.0, 0.0)
    core.handle(cmd(1.0), 12 * WATCHDOG_NS)
    assert core.state is DriverState.RUNNING and core.counters.commands == 2


def test_estop_latches_from_every_state_and_zeroes_output() -> None:
    for setup in ("init", "running", "fault"):
        core = make_core()
        if setup != "init":
            core.handle(cmd(2.0), 0)
        if setup == "fault":
            core.check_watchdog(WATCHDOG_NS + 1)
        core.handle(EStop(NODE), WATCHDOG_NS + 2)
        assert core.state is DriverState.ESTOP and core.voltage_v == (0.0, 0.0), setup
        core.handle(cmd(2.0), WATCHDOG_NS + 3)
        core.check_watchdog(10 * WATCHDOG_NS)   # the watchdog does not turn ESTOP into FAULT
        assert core.state is DriverState.ESTOP and ErrorFlags.ESTOP in core.flags, setup


@pytest.mark.parametrize("v,applied", [((30.0, -30.0), (24.0, -24.0)), ((24.5, 0.0), (24.0, 0.0)),
                                       ((0.0, -25.0), (0.0, -24.0))])
def test_saturation_to_limit_sets_flag(v: tuple[float, float], applied: tuple[float, float]) -> None:
    core = make_core()
    assert core.params.voltage_limit == 24.0
    core.handle(VoltageCmd(NODE, v, 0), 0)
    assert core.voltage_v == applied and ErrorFlags.SATURATED in core.flags


def test_in_range_voltage_does_not_set_saturated() -> None:
    core = make_core()
    core.handle(cmd(24.0, -24.0), 0)
    assert core.voltage_v == (24.0, -24.0) and ErrorFlags.SATURATED not in core.flags


def test_heartbeat_contents_and_rolling_seq() -> None:
    core = make_core(node_id=5)
    core.reject()
    core.reject()
    core.counters.overruns = 3
    hb = core.heartbeat()
    assert hb == Heartbeat(5, DriverState.INIT, ErrorFlags.BAD_FRAME, 2, 3, 1)
    core.counters.rejected_frames = 70_000          # saturates at the 16-bit field
    core.handle(VoltageCmd(5, (25.0, 0.0), 0), 0)
    hb = core.heartbeat()
    assert hb.state is DriverState.RUNNING and hb.rejected_frames == 0xFFFF and hb.seq == 2
    assert hb.flags == ErrorFlags.BAD_FRAME | ErrorFlags.SATURATED
    SeaCodec([5]).encode(hb)                           # encodable as it is
    seqs = [core.heartbeat().seq for _ in range(300)]
    assert seqs[252:255] == [0xFF, 0, 1] and all(0 <= s <= 0xFF for s in seqs)


def test_feedback_seq_rolls_over_at_256_and_t_us_wraps() -> None:
    core = make_core()
    seqs = [core.step().seq for _ in range(260)]
    assert seqs[:3] == [1, 2, 3] and seqs[254:258] == [255, 0, 1, 2]
    assert core.feedback().t_us == 260_000 % 65_536   # rolling 16-bit microseconds


def test_step_matches_pure_model_under_voltage() -> None:
    core = make_core()
    cfg = load_config()
    p = limb_params(cfg.plant)
    x = initial_state(*cfg.plant.initial_theta_rad, 0.0, 0.0, p)
    core.handle(cmd(2.0, -1.0), 0)
    for k in range(50):
        x = advance(k * PERIOD_NS * 1e-9, x, (2.0, -1.0), PERIOD_NS * 1e-9, cfg.sim.substeps, p, _no_dist)
        fb = core.step()
    assert fb.theta_rad == (x[0], x[1]) and fb.nut_vel_m_s == (x[6], x[7])
    assert abs(x[0] - cfg.plant.initial_theta_rad[0]) > 1e-4   # the voltage did move the joint


def test_overruns_are_counted_and_flagged() -> None:
    core = make_core()
    core.note_overruns(2)
    core.note_overruns(1)
    hb = core.heartbeat()
    assert hb.overruns == 3 and hb.flags == ErrorFlags.OVERRUN


def test_clear_errors_resets_heartbeat_counters() -> None:
    core = make_core()
    core.reject()
    core.note_overruns(4)
    core.handle(ClearErrors(NODE), 0)
    hb = core.heartbeat()
    assert (hb.rejected_frames, hb.overruns, hb.flags) == (0, 0, ErrorFlags(0))


def test_real_time_command_acts_from_its_arrival_in_the_period() -> None:
    """A real drive applies a voltage when the frame arrives: the period is integrated piecewise."""
    cfg = load_config()
    p = limb_params(cfg.plant)
    core, ref = make_core(), make_core()
    core.handle(cmd(1.0), 0)
    ref.handle(cmd(1.0), 0)
    core.step()
    ref.step()
    x = core.x
    t0_ns = 7_000_000_000
    core.period_start_ns = t0_ns
    core.handle(cmd(-3.0, 2.0), t0_ns + PERIOD_NS // 4)   # arrives a quarter period in
    fb = core.step()
    t_s = PERIOD_NS * 1e-9
    n1 = -(-cfg.sim.substeps // 4)                        # ceil(substeps / 4)
    n2 = -(-cfg.sim.substeps * 3 // 4)
    x = advance(t_s, x, (1.0, 0.0), t_s / 4, n1, p, _no_dist)
    x = advance(t_s + t_s / 4, x, (-3.0, 2.0), t_s * 3 / 4, n2, p, _no_dist)
    assert fb.theta_rad == pytest.approx((x[0], x[1]), abs=1e-12)
    assert fb.omega_rad_s == pytest.approx((x[2], x[3]), abs=1e-10)
    ref.handle(cmd(-3.0, 2.0), 0)                           # the same command from the period start differs
    assert abs(ref.step().omega_rad_s[0] - fb.omega_rad_s[0]) > 1e-6
    late = make_core()
    late.period_start_ns = t0_ns
    late.handle(cmd(5.0), t0_ns + 3 * PERIOD_NS)           # after the period: clamped to its end, acts next period
    assert late.step().omega_rad_s == pytest.approx(make_core().step().omega_rad_s, abs=0.0)
    assert late.voltage_v == (5.0, 0.0)


def test_e_stop_acts_on_arrival_too() -> None:
    cfg = load_config()
    p = limb_params(cfg.plant)
    core = make_core()
    core.handle(cmd(4.0), 0)
    core.step()
    x = core.x
    core.period_start_ns = 0
    core.handle(EStop(NODE), PERIOD_NS // 2)
    fb = core.step()
    assert core.voltage_v == (0.0, 0.0) and core.state is DriverState.ESTOP
    t_s, n = PERIOD_NS * 1e-9, -(-cfg.sim.substeps // 2)
    x = advance(t_s, x, (4.0, 0.0), t_s / 2, n, p, _no_dist)      # 4 V until the e-stop arrived, then none
    x = advance(t_s + t_s / 2, x, (0.0, 0.0), t_s / 2, n, p, _no_dist)
    assert fb.omega_rad_s == pytest.approx((x[2], x[3]), abs=1e-10)
