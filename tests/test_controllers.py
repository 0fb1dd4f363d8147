"""SMC (Eq. 12-13), event trigger (Eq. 16-19 + Sec. 4 rules), backstepping (Eq. 24-31), inner and outer loops."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.backstepping import InnerGains, backstepping_voltage, cross_term_weight
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.outer import OuterController
from sea_hil.controller.smc import JointState, sliding_surface, smc_deflection, switching, tracking_errors
from sea_hil.controller.trajectory import DesiredSample, GaitTrajectory
from sea_hil.controller.trigger import EventTrigger, TimeTrigger, epsilon, error_threshold
from sea_hil.dynamics import deflections, f, initial_state
from sea_hil.mechanics import LimbParams, fx_gx, limb_params, mass_matrix, sea_geometry, sea_lengths
from sea_hil.protocol.payloads import TriggerReason

S = 1_000_000_000


@pytest.fixture(scope="module")
def cfg() -> SeaHilConfig:
    return load_config()


@pytest.fixture(scope="module")
def p(cfg: SeaHilConfig) -> LimbParams:
    return limb_params(cfg.plant)


# ---- SMC -----------------------------------------------------------------------------------------------------------

def test_sliding_surface_eq12() -> None:
    js = JointState((0.3, 0.5), (1.0, -2.0))
    ds = DesiredSample((0.1, 0.6), (0.5, -1.0), (0.0, 0.0))
    xt = tracking_errors(js, ds)
    assert xt == pytest.approx((0.2, -0.1, 0.5, -1.0))
    assert sliding_surface(xt, 30.0) == pytest.approx((30 * 0.2 + 0.5, 30 * -0.1 - 1.0))


def test_switching_sign_and_boundary_layer() -> None:
    assert [switching(v, 0.0) for v in (-2.0, -1e-12, 0.0, 1e-12, 3.0)] == [-1.0, -1.0, 0.0, 1.0, 1.0]
    assert [switching(v, 0.5) for v in (-2.0, -0.5, -0.25, 0.0, 0.1, 0.5, 0.7)] == \
        pytest.approx([-1.0, -1.0, -0.5, 0.0, 0.2, 1.0, 1.0])


def _smc_case(seed: int) -> tuple[JointState, DesiredSample]:
    rng = np.random.default_rng(seed)
    js = JointState((rng.uniform(-0.3, 0.4), rng.uniform(0.2, 1.0)), tuple(rng.uniform(-1.5, 1.5, 2)))
    ds = DesiredSample((js.theta_rad[0] + rng.normal(0, 0.01), js.theta_rad[1] + rng.normal(0, 0.01)),
                       tuple(rng.uniform(-1, 1, 2)), tuple(rng.uniform(-3, 3, 2)))
    return js, ds


@pytest.mark.parametrize("boundary_layer", [0.0, 1.0])
def test_smc_deflection_gives_the_designed_joint_acceleration(p: LimbParams, boundary_layer: float) -> None:
    """Eq. 13 with the nominal model, d = 0, and v_x applied exactly: theta_dd = xdd_d - c x~2 - rho switching(s)."""
    c, rho = 30.0, 20.0
    for seed in range(10):
        js, ds = _smc_case(seed)
        (v1, v2), s = smc_deflection(js, ds, p, c, rho, boundary_layer)
        xt = tracking_errors(js, ds)
        want = (ds.alpha_rad_s2[0] - c * xt[2] - rho * switching(s[0], boundary_layer),
                ds.alpha_rad_s2[1] - c * xt[3] - rho * switching(s[1], boundary_layer))
        (q1, q2), (w1, w2) = js.theta_rad, js.omega_rad_s
        _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
        f1, f2, g = fx_gx(q1, q2, w1, w2, a1, a2, p)
        assert (f1 + g[0] * v1 + g[1] * v2, f2 + g[2] * v1 + g[3] * v2) == pytest.approx(want, rel=1e-9, abs=1e-9)
        # the same through the plant: put the nuts where the spring deflections equal v_x
        len1, len2 = sea_lengths(q1, q2, p)
        x = (q1, q2, w1, w2, len1 - p.l_ref[0] - v1, len2 - p.l_ref[1] - v2, 0.0, 0.0)
        assert deflections(x, p)[0:2] == pytest.approx((v1, v2), abs=1e-15)
        assert f(0.0, x, (0.0, 0.0), p)[2:4] == pytest.approx(want, rel=1e-8, abs=1e-8)
        if boundary_layer == 0.0:
            assert abs(s[0]) > 0 and abs(s[1]) > 0  # so sign(s) really contributed +-rho


# ---- trigger -------------------------------------------------------------------------------------------------------

def test_error_threshold_eq19_paper_numbers() -> None:
    assert error_threshold(0.3, 0.85, 30.0) == pytest.approx(0.3 / (0.85 * math.sqrt(901.0)), rel=1e-15)
    assert error_threshold(0.3, 0.85, 30.0) == pytest.approx(0.011758, abs=1e-6)


def test_epsilon_stacks_tracking_error_and_desired_state() -> None:
    assert epsilon((1, 2, 3, 4), (5, 6), (7, 8)) == (1, 2, 3, 4, 5, 6, 7, 8)


def _eps(xt: tuple[float, float, float, float] = (0, 0, 0, 0), xd: tuple[float, float] = (0.1, 0.5),
         xdd: tuple[float, float] = (0.2, -0.3)) -> tuple[float, ...]:
    return epsilon(xt, xd, xdd)


def test_event_trigger_rules() -> None:
    th, r = 0.0117, 0.2
    trig = EventTrigger(th, r, max_inter_event_ns=S // 4)
    base = _eps()
    assert trig.update(0, base) is TriggerReason.INITIAL
    assert trig.update(10_000_000, base) is None
    # ||e|| just below / at the threshold (e on the desired-state part, X~ stays 0)
    assert trig.update(20_000_000, _eps(xd=(0.1 + 0.999 * th, 0.5))) is None
    assert trig.update(30_000_000, _eps(xd=(0.1, 0.5 + th))) is TriggerReason.ERROR_BOUND
    # the reference moved to the event sample: the same eps no longer fires
    assert trig.update(40_000_000, _eps(xd=(0.1, 0.5 + th))) is None
    # the 2-norm combines components: two changes of 0.75 th each (norm 1.06 th) fire, 0.7 th each (0.99 th) not
    def two_changes(k: float) -> tuple[float, ...]:
        return _eps(xt=(0.0, 0.0, k * th, 0.0), xd=(0.1, 0.5 + th), xdd=(0.2, -0.3 + k * th))

    assert trig.update(50_000_000, two_changes(0.7)) is None
    assert trig.update(60_000_000, two_changes(0.75)) is TriggerReason.ERROR_BOUND


def test_tracking_bound_fires_while_error_exceeds_r() -> None:
    trig = EventTrigger(0.05, 0.2, max_inter_event_ns=S)
    big = _eps(xt=(0.15, 0.0, 0.0, 0.14))  # ||X~|| = 0.205 > r
    assert trig.update(0, big) is TriggerReason.INITIAL
    assert trig.update(10_000_000, big) is TriggerReason.TRACKING_BOUND  # e = 0 but X~ too large
    assert trig.update(20_000_000, big) is TriggerReason.TRACKING_BOUND
    at_r = _eps(xt=(0.12, 0.0, 0.16, 0.0))  # ||X~|| == 0.2 exactly is allowed (strict >)
    trig2 = EventTrigger(0.05, 0.2, max_inter_event_ns=S)
    trig2.update(0, at_r)
    assert trig2.update(10_000_000, at_r) is None


def test_error_bound_takes_precedence_over_tracking_bound() -> None:
    trig = EventTrigger(0.05, 0.2, max_inter_event_ns=S)
    trig.update(0, _eps(xt=(0.3, 0, 0, 0)))
    assert trig.update(10_000_000, _eps(xt=(0.4, 0, 0, 0))) is TriggerReason.ERROR_BOUND


def test_heartbeat_after_max_inter_event_time() -> None:
    trig = EventTrigger(0.05, 0.2, max_inter_event_ns=250_000_000)
    assert trig.update(1 * S, _eps()) is TriggerReason.INITIAL
    assert trig.update(1 * S + 249_999_999, _eps()) is None
    assert trig.update(1 * S + 250_000_000, _eps()) is TriggerReason.HEARTBEAT
    assert trig.update(1 * S + 260_000_000, _eps()) is None  # timer restarted at the heartbeat
    assert trig.update(1 * S + 500_000_000, _eps()) is TriggerReason.HEARTBEAT


def test_time_trigger_always_fires() -> None:
    trig = TimeTrigger()
    assert all(trig.update(k * 10_000_000, _eps()) is TriggerReason.TIME for k in range(5))


def test_outer_controller_modes(cfg: SeaHilConfig, p: LimbParams) -> None:
    ds = GaitTrajectory(10.0).sample(0.0)
    js = JointState(ds.theta_rad, ds.omega_rad_s)
    et, tt = OuterController(cfg, p, "et"), OuterController(cfg, p, "tt")
    sp = et.step(0, 7, js, ds)
    assert sp is not None and sp.reason is TriggerReason.INITIAL and sp.state_seq == 7 and sp.t_ns == 0
    vx, s = smc_deflection(js, ds, p, cfg.controller.c, cfg.controller.rho, cfg.controller.boundary_layer)
    assert sp.deflection_m == vx and sp.sliding == s
    assert et.step(10_000_000, 8, js, ds) is None
    assert all(tt.step(k * 10_000_000, k, js, ds).reason is TriggerReason.TIME for k in range(3))
    with pytest.raises(ValueError, match="'tt' or 'et'"):
        OuterController(cfg, p, "xx")


# ---- backstepping --------------------------------------------------------------------------------------------------

def _g_matrix(q1: float, q2: float, p: LimbParams) -> np.ndarray:
    m11, m12, m22 = mass_matrix(q2, p)
    _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
    return np.linalg.solve(np.array([[m11, -m12], [-m12, m22]]), np.diag([-p.k1 * a1, -p.k2 * a2]))


@pytest.mark.parametrize("weight", ["off", "normalized", "paper"])
def test_backstepping_gives_the_designed_deflection_dynamics(cfg: SeaHilConfig, p: LimbParams, weight: str) -> None:
    """Eq. 31 on the exact model: Delta_dd = kp2 (v1 - z2) + v1_dot + (v_x - z1), v1 from Eq. 27 with v_x held."""
    w = cross_term_weight(weight, p, 30.0, (0.05, 0.55))
    gains = InnerGains(60.0, 100.0, w)
    rng = np.random.default_rng(11)
    for _ in range(10):
        q1, q2 = rng.uniform(-0.3, 0.4), rng.uniform(0.2, 1.0)
        x0 = initial_state(q1, q2, *rng.uniform(-1.5, 1.5, 2), p)
        nut = np.array(x0[4:6]) + rng.uniform(-1e-3, 1e-3, 2)
        x = x0[:4] + tuple(nut) + tuple(rng.uniform(-0.02, 0.02, 2))
        z1 = np.array(deflections(x, p)[0:2])
        z2 = np.array(deflections(x, p)[2:4])
        m = (x[0], x[1], x[2], x[3], z1[0], z1[1], x[6], x[7])
        vx = z1 + rng.uniform(-1e-3, 1e-3, 2)
        s = rng.uniform(-0.5, 0.5, 2)
        u = backstepping_voltage(m, tuple(vx), tuple(s), p, gains)
        # Delta_dd along the plant's motion: directional derivative of Delta_dot(x) along f(x, u), d = 0
        xdot = f(0.0, x, u, p)
        h = 1e-6
        ddp = deflections(tuple(a + h * b for a, b in zip(x, xdot, strict=True)), p)[2:4]
        ddm = deflections(tuple(a - h * b for a, b in zip(x, xdot, strict=True)), p)[2:4]
        delta_dd = (np.array(ddp) - np.array(ddm)) / (2 * h)
        # designed v1 and v1_dot (s and v_x held): g_dot by a central difference along the joint velocity
        hg = 1e-6
        gdot = (_g_matrix(x[0] + hg * x[2], x[1] + hg * x[3], p)
                - _g_matrix(x[0] - hg * x[2], x[1] - hg * x[3], p)) / (2 * hg)
        g = _g_matrix(x[0], x[1], p)
        v1 = gains.kp1 * (vx - z1) - w * g.T @ s
        v1_dot = -gains.kp1 * z2 - w * gdot.T @ s
        want = gains.kp2 * (v1 - z2) + v1_dot + (vx - z1)
        scale = max(1.0, float(np.abs(want).max()))
        assert np.abs(delta_dd - want).max() < 1e-6 * scale, (weight, delta_dd, want)


def test_cross_term_weight_modes(p: LimbParams) -> None:
    assert cross_term_weight("paper", p, 30.0, (0.05, 0.55)) == 1.0
    assert cross_term_weight("off", p, 30.0, (0.05, 0.55)) == 0.0
    w = cross_term_weight("normalized", p, 30.0, (0.05, 0.55))
    assert math.sqrt(w) * np.linalg.norm(_g_matrix(0.05, 0.55, p)) == pytest.approx(30.0, rel=1e-9)


def test_inner_loop_holds_measured_deflection_and_saturates(cfg: SeaHilConfig, p: LimbParams) -> None:
    x = initial_state(0.05, 0.55, 0.0, 0.0, p)
    dl = deflections(x, p)
    m = (x[0], x[1], x[2], x[3], dl[0], dl[1], x[6], x[7])
    loop = InnerLoop(cfg, p, (0.05, 0.55))
    # at rest in equilibrium with no setpoint yet: hold the deflection -> no voltage
    assert loop.voltage(m) == pytest.approx((0.0, 0.0), abs=1e-9)
    loop.hold((dl[0] + 0.05, dl[1] - 0.05), (0.0, 0.0))  # 5 cm deflection error: far beyond 24 V
    assert loop.voltage(m) == (-24.0, 24.0)  # positive deflection error -> pull the nut back (Eq. 31 sign)
    assert loop.saturated_steps == 1
    loop.hold((float("nan"), 0.0), (0.0, 0.0))
    assert loop.voltage(m) == (0.0, 0.0)
