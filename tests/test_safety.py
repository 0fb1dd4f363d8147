"""The safety envelope (issue 19 item 4): the plant's mechanical end stops (energy-consistent, inactive inside), the
drive's soft limits (each faults the drive with its own heartbeat flag; the limb stays inside its end stops) and the
edge's setpoint envelope (an out-of-envelope SETPOINT is rejected, counted and never applied)."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sea_hil.config.loader import load_config
from sea_hil.dynamics import end_stop_energy, end_stop_torque, f, initial_state
from sea_hil.errors import ConfigError
from sea_hil.jit import loaded
from sea_hil.mechanics import energy, limb_params
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.plant_emulator.integrator import advance, make_advance_kernel, prepare_advance
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import ClearErrors, DriverState, ErrorFlags, FeedbackAngle, VoltageCmd

NODE = 1
CFG = load_config()
P = limb_params(CFG.plant)


def _no_dist(t: float) -> tuple[float, float]:
    return (0.0, 0.0)


# ---- end stops ----------------------------------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(q=st.floats(-3.0, 3.0), w=st.floats(-50.0, 50.0), k=st.floats(1.0, 1e5), c=st.floats(0.0, 100.0))
def test_end_stop_only_dissipates_and_never_pulls(q: float, w: float, k: float, c: float) -> None:
    lo, hi = -0.5, 1.6
    tau = end_stop_torque(q, w, lo, hi, k, c)
    pen = max(q - hi, lo - q, 0.0)
    pen_rate = w if q > hi else (-w if q < lo else 0.0)
    # d/dt (joint energy + stop spring energy) = tau w + k pen pen_rate: never positive
    assert tau * w + k * pen * pen_rate <= 1e-9 * (1.0 + abs(tau * w))
    if q > hi:
        assert tau <= 0.0          # pushes back into the range, never pulls outward
    elif q < lo:
        assert tau >= 0.0
    else:
        assert tau == 0.0


def test_end_stops_inactive_inside_bit_for_bit() -> None:
    off = limb_params(load_config(overrides={"plant": {"end_stops": {"enabled": False}}}).plant)
    for q1, q2, w1, w2 in ((0.05, 0.28, 0.3, -0.2), (-0.99, -0.49, -5.0, 5.0), (1.09, 1.59, 5.0, 5.0)):
        x = initial_state(q1, q2, w1, w2, P)
        assert f(0.0, x, (3.0, -2.0), P) == f(0.0, x, (3.0, -2.0), off)


def _released_against_stop(p, joint: int, spring_rest_rad: float, start_rad: float):   # type: ignore[no-untyped-def]
    """Nut locked (u = 0, nut at rest) where the SEA spring holds the joint at `spring_rest_rad`, beyond an end stop;
    the joint starts at rest at `start_rad`: the spring throws it into the stop."""
    q = [0.05, 0.55]
    q[joint] = spring_rest_rad
    x = list(initial_state(q[0], q[1], 0.0, 0.0, p))
    x[joint] = start_rad
    return tuple(x)


CASES = [(1, 1.8, 1.5), (1, -0.75, -0.4), (0, 1.35, 1.0), (0, -1.25, -0.9)]   # joint, spring rest, start


@pytest.mark.parametrize("joint,rest,start", CASES)
def test_end_stop_impact_dissipates_and_holds(joint: int, rest: float, start: float) -> None:
    """No joint friction, nut locked: the only loss is the stop's damper. The total energy (limb + SEA spring + stop
    spring) never rises (to 1e-5 J, RK4's error at the contact), falls over the impacts, and the joint stays within a
    small penetration of its stop."""
    p = limb_params(load_config(overrides={"plant": {"b1_nms": 0.0, "b2_nms": 0.0}}).plant)
    x = _released_against_stop(p, joint, rest, start)
    e0 = e_prev = energy(x, p) + end_stop_energy(x, p)
    max_pen = 0.0
    for k in range(2000):
        x = advance(k * 1e-3, x, (0.0, 0.0), 1e-3, 2, p, jit=False)
        e = energy(x, p) + end_stop_energy(x, p)
        assert e <= e_prev + 1e-5, f"energy rose by {e - e_prev} J at sample {k}"
        e_prev = e
        max_pen = max(max_pen, x[joint] - p.stop_max_rad[joint], p.stop_min_rad[joint] - x[joint])
    assert max_pen > 0.0                     # the stop was hit ...
    assert max_pen < 0.2                     # ... and held the joint
    assert e0 - e > 0.25                     # the impacts dissipated energy (measured 0.5-10.7 J over the cases)


def test_end_stop_contact_same_floats_in_the_compiled_kernel() -> None:
    if not prepare_advance(P) or loaded(make_advance_kernel) is None:
        pytest.skip("numba not installed")
    x_jit = x_py = _released_against_stop(P, 1, 1.8, 1.5)
    for k in range(300):
        x_jit = advance(k * 1e-3, x_jit, (0.0, 0.0), 1e-3, 2, P)
        x_py = advance(k * 1e-3, x_py, (0.0, 0.0), 1e-3, 2, P, jit=False)
    assert x_jit == x_py and x_py[1] > P.stop_max_rad[1] - 0.05


# ---- drive soft limits ----------------------------------------------------------------------------------------------
def _core() -> DriverCore:
    return DriverCore.create(NODE, P, 1e-3, 0.1, CFG.sim.substeps, tuple(CFG.plant.initial_theta_rad), _no_dist,
                             DriveLimits.from_config(CFG.safety.drive))


# (voltage, flag): a slow hip creep reaches the position limit; a 24 V knee step the velocity limit (the light shank
# accelerates before its spring deflects); a 24 V hip step the force limit (the heavy thigh lags its nut)
LIMIT_CASES = [((1.5, 0.0), ErrorFlags.POSITION_LIMIT), ((0.0, -1.5), ErrorFlags.POSITION_LIMIT),
               ((0.0, 24.0), ErrorFlags.VELOCITY_LIMIT), ((24.0, 0.0), ErrorFlags.FORCE_LIMIT),
               ((-24.0, 0.0), ErrorFlags.FORCE_LIMIT)]


@pytest.mark.parametrize("u,flag", LIMIT_CASES, ids=[f"{c[1].name}{c[0]}" for c in LIMIT_CASES])
def test_each_limit_faults_the_drive_with_its_flag(u: tuple[float, float], flag: ErrorFlags) -> None:
    core, codec = _core(), SeaCodec([NODE])
    lim, stops = CFG.safety.drive, CFG.plant.end_stops
    fault_sample = None
    for k in range(4000):                                     # commanded like the edge: one VOLTAGE_CMD per sample
        core.handle(VoltageCmd(NODE, u, k & 0xFF), k * 1_000_000)
        fb = core.step()
        for j in range(2):
            assert stops.min_rad[j] < fb.theta_rad[j] < stops.max_rad[j]   # never reaches an end stop
        if fault_sample is None and core.state is DriverState.FAULT:
            fault_sample = fb
            assert core.flags == flag and core.voltage_v == (0.0, 0.0)
    assert fault_sample is not None, "the limit was never reached"
    j = 0 if u[0] else 1
    if flag is ErrorFlags.POSITION_LIMIT:
        assert not lim.position_min_rad[j] <= fault_sample.theta_rad[j] <= lim.position_max_rad[j]
    elif flag is ErrorFlags.VELOCITY_LIMIT:
        assert abs(fault_sample.omega_rad_s[j]) > lim.velocity_max_rad_s[j]
    else:
        assert abs(fault_sample.delta_m[j]) * (P.k1, P.k2)[j] > lim.spring_force_max_n[j]
    hb = codec.decode(codec.encode(core.heartbeat()))       # the flag crosses the wire in its own DBC bit
    assert hb.state is DriverState.FAULT and hb.flags == flag
    assert core.counters.limit_trips == 1 and core.counters.ignored_commands > 0   # commands ignored while faulted
    core.handle(ClearErrors(NODE), 0)                        # clear-errors as today: INIT, flags cleared
    assert core.state is DriverState.INIT and core.flags == ErrorFlags(0)


def test_limits_disabled_and_checked_only_while_running() -> None:
    none = DriveLimits.from_config(load_config(overrides={"safety": {"drive": {"enabled": False}}}).safety.drive)
    assert none.violations((9.0, -9.0), (99.0, 99.0), (0.03, 0.03), P) == ErrorFlags(0)
    lim = DriveLimits.from_config(CFG.safety.drive)
    assert lim.violations((0.05, 0.28), (0.0, 0.0), (0.0, 0.0), P) == ErrorFlags(0)
    assert lim.violations((math.nan, 0.28), (0.0, math.nan), (0.0, math.nan), P) == \
        ErrorFlags.POSITION_LIMIT | ErrorFlags.VELOCITY_LIMIT | ErrorFlags.FORCE_LIMIT
    core = _core()
    core.x = initial_state(0.9, 0.28, 0.0, 0.0, P)   # outside the position limit, but not RUNNING: no fault
    core.step()
    assert core.state is DriverState.INIT and core.flags == ErrorFlags(0)
    core.handle(VoltageCmd(NODE, (0.0, 0.0), 0), 0)
    core.step()
    assert core.state is DriverState.FAULT and core.flags == ErrorFlags.POSITION_LIMIT


def test_limit_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="minimum"):
        load_config(overrides={"safety": {"drive": {"position_min_rad": [0.7, 0.0]}}})
    with pytest.raises(ConfigError, match="velocity_max_rad_s"):
        load_config(overrides={"safety": {"drive": {"velocity_max_rad_s": [0.0, 1.0]}}})
    with pytest.raises(ConfigError, match="end_stops"):
        load_config(overrides={"plant": {"end_stops": {"min_rad": [2.0, -0.5]}}})


def test_plant_node_reports_a_limit_fault_over_can() -> None:
    """End to end on a CAN bus (lockstep `PlantNode`, a peer answering every feedback with a 24 V hip step like a
    runaway edge): the heartbeat reports FAULT with err_force_limit and the limb never reaches its end stops."""
    from test_plant_node import is_hb, running_node  # the node test's virtual-bus helpers

    seen: list[float] = []
    with running_node(CFG, lockstep=True) as (node, peer):
        def answer(frame: object) -> None:
            if isinstance(frame, FeedbackAngle):     # the first of a sample's three frames
                seen.append(frame.theta_rad[0])
                peer.send(VoltageCmd(NODE, (24.0, 0.0), frame.seq))
        hb = peer.wait_for(is_hb(DriverState.FAULT), timeout_s=30.0, on_frame=answer)
        assert hb.flags & ~ErrorFlags.OVERRUN == ErrorFlags.FORCE_LIMIT
        assert node.drivers[NODE].counters.limit_trips == 1 and node.drivers[NODE].voltage_v == (0.0, 0.0)
    stops = CFG.plant.end_stops
    assert seen and all(stops.min_rad[0] < q < stops.max_rad[0] for q in seen)
