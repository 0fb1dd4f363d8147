"""Plant dynamics (Eq. 3-7): independent Lagrangian, energy balance, RK4 vs scipy, equilibrium, disturbance."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sea_hil.config.loader import load_config
from sea_hil.config.model import DisturbanceConfig
from sea_hil.dynamics import deflections, f, initial_state, is_finite, saturate
from sea_hil.mechanics import LimbParams, energy, limb_params, sea_lengths
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.integrator import advance


def _params(**plant: object) -> LimbParams:
    return limb_params(load_config(overrides={"plant": plant} if plant else None).plant)


@pytest.fixture(scope="module")
def p() -> LimbParams:
    return _params()


# ---- an independent Lagrangian of the two-link pendulum with two SEA springs -------------------------------------
# theta1 from the downward vertical, link 2's absolute angle phi = theta1 - theta2 (paper Fig. 1 / Eq. 2 convention).

def _mass_matrix(q: np.ndarray, p: LimbParams) -> np.ndarray:
    """M(q) = sum m J^T J + rotational inertias, from the centre-of-mass Jacobians (not from Eq. 2)."""
    q1, q2 = q
    phi = q1 - q2
    j1 = np.array([[p.r1 * math.cos(q1), 0.0], [p.r1 * math.sin(q1), 0.0]])
    j2 = np.array([[p.l1 * math.cos(q1) + p.r2 * math.cos(phi), -p.r2 * math.cos(phi)],
                   [p.l1 * math.sin(q1) + p.r2 * math.sin(phi), -p.r2 * math.sin(phi)]])
    e1, e_phi = np.array([1.0, 0.0]), np.array([1.0, -1.0])
    return (p.m1 * j1.T @ j1 + p.m2 * j2.T @ j2 + p.i1 * np.outer(e1, e1) + p.i2 * np.outer(e_phi, e_phi))


def _potential(q: np.ndarray, r: np.ndarray, p: LimbParams) -> float:
    q1, q2 = q
    y1 = -p.r1 * math.cos(q1)
    y2 = -p.l1 * math.cos(q1) - p.r2 * math.cos(q1 - q2)
    len1, len2 = sea_lengths(q1, q2, p)
    dl = np.array([len1 - p.l_ref[0], len2 - p.l_ref[1]]) - r
    return p.g * (p.m1 * y1 + p.m2 * y2) + 0.5 * (p.k1 * dl[0] ** 2 + p.k2 * dl[1] ** 2)


def _lagrange_acc(x: tuple[float, ...], d_nm: tuple[float, float], p: LimbParams) -> np.ndarray:
    """Solve d/dt dT/dw - dT/dq + dV/dq = -B w + d for the joint accelerations, derivatives by central differences."""
    q, w, r = np.array(x[0:2]), np.array(x[2:4]), np.array(x[4:6])
    h = 1e-6
    dm = [(_mass_matrix(q + h * e, p) - _mass_matrix(q - h * e, p)) / (2 * h) for e in np.eye(2)]
    dv = np.array([(_potential(q + h * e, r, p) - _potential(q - h * e, r, p)) / (2 * h) for e in np.eye(2)])
    m_dot_w = sum(dm[j] * w[j] for j in range(2)) @ w
    dt_dq = np.array([0.5 * w @ dm[i] @ w for i in range(2)])
    rhs = -m_dot_w + dt_dq - dv - np.array([p.b1 * w[0], p.b2 * w[1]]) + np.array(d_nm)
    return np.linalg.solve(_mass_matrix(q, p), rhs)


def _random_states(n: int, seed: int, p: LimbParams) -> list[tuple[float, ...]]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        q1, q2 = rng.uniform(-0.4, 0.4), rng.uniform(0.1, 1.1)
        x0 = initial_state(q1, q2, 0.0, 0.0, p)
        dr = rng.uniform(-3e-3, 3e-3, 2)
        out.append((q1, q2, *rng.uniform(-3, 3, 2), x0[4] + dr[0], x0[5] + dr[1], *rng.uniform(-0.05, 0.05, 2)))
    return out


def test_joint_accelerations_match_an_independent_lagrangian(p: LimbParams) -> None:
    rng = np.random.default_rng(7)
    for x in _random_states(25, 1, p):
        d_nm = tuple(rng.uniform(-2, 2, 2))
        dx = f(0.0, x, (1.0, -2.0), p, d_nm)
        want = _lagrange_acc(x, d_nm, p)
        assert dx[2:4] == pytest.approx(tuple(want), rel=1e-6, abs=1e-5)
        assert dx[0:2] == x[2:4] and dx[4:6] == x[6:8]
        assert dx[6] == pytest.approx(1.0 - p.nut_damping * x[6])
        assert dx[7] == pytest.approx(-2.0 - p.nut_damping * x[7])


def test_lagrangian_check_can_fail_without_i2_coupling() -> None:
    """The paper's literal M (Eq. 2 without I2 in M11/M12) is not the Lagrangian of this pendulum."""
    p = _params(include_i2_in_coupling=False)
    x = _random_states(1, 2, p)[0]
    dx = f(0.0, x, (0.0, 0.0), p)
    assert max(abs(a - b) for a, b in zip(dx[2:4], _lagrange_acc(x, (0.0, 0.0), p), strict=True)) > 1e-2


def test_energy_function_matches_the_independent_lagrangian(p: LimbParams) -> None:
    for x in _random_states(10, 3, p):
        w = np.array(x[2:4])
        want = 0.5 * w @ _mass_matrix(np.array(x[0:2]), p) @ w + _potential(np.array(x[0:2]), np.array(x[4:6]), p)
        assert energy(x, p) == pytest.approx(want, rel=1e-12, abs=1e-12)


def _energy_trace(p: LimbParams, seconds: float) -> np.ndarray:
    x = initial_state(0.2, 0.7, 1.0, -1.5, p)  # nut velocity 0 and u = 0: the nut stays locked (rdd = u - 48 rd = 0)
    out = [energy(x, p)]
    for k in range(int(round(seconds / 1e-3))):
        x = advance(k * 1e-3, x, (0.0, 0.0), 1e-3, 2, p)
        out.append(energy(x, p))
    assert x[6] == 0.0 and x[7] == 0.0
    return np.array(out)


def test_energy_is_conserved_without_friction() -> None:
    p = _params(b1_nms=0.0, b2_nms=0.0)
    e = _energy_trace(p, 2.0)
    kinetic0 = e[0] - energy(initial_state(0.2, 0.7, 0.0, 0.0, p), p)
    assert kinetic0 > 0.05  # the test really moves the limb
    # RK4 (h = 0.5 ms) dissipates O(h^4): measured ~2e-6 of the kinetic energy over 2 s; friction 0.3 Nms removes
    # most of it, and a wrong Coriolis/gravity term would not conserve energy at all
    assert np.abs(e - e[0]).max() < 1e-5 * kinetic0


def test_energy_decreases_with_friction(p: LimbParams) -> None:
    assert p.b1 > 0 and p.b2 > 0
    e = _energy_trace(p, 2.0)
    assert np.all(np.diff(e) < 1e-9)
    assert e[0] - e[-1] > 0.05 * (e[0] - energy(initial_state(0.2, 0.7, 0.0, 0.0, p), p))


def _rk4_path(x0: tuple[float, ...], u: tuple[float, float], dist, p: LimbParams, dt: float, substeps: int,
              seconds: float) -> np.ndarray:
    x, out = x0, [x0]
    for k in range(int(round(seconds / dt))):
        x = advance(k * dt, x, u, dt, substeps, p, dist)
        out.append(x)
    return np.array(out)


def test_rk4_matches_scipy_dop853(p: LimbParams) -> None:
    """Simulator step (1 ms, 2 RK4 sub-steps) vs DOP853 at rtol 1e-10 over 0.5 s, constant voltage, sine disturbance.

    Tolerance: RK4's global error is O(h^4). Measured with h = 0.5 ms while the limb swings ~0.35 rad: ~1.4e-8 rad,
    ~3.3e-6 rad/s, ~1e-12 m, ~6e-11 m/s; DOP853 itself agrees with Radau to ~1e-11 rad, so it is an exact reference
    here. The bounds below are ~7x those values: a wrong RK4 weight or stage time drops the order and fails them,
    and halving h must shrink the error by ~16x (fourth order).
    """
    dist = make_disturbance(DisturbanceConfig(kind="sine", amplitude_nm=(1.5, 0.8), frequency_hz=3.0))
    u = (3.0, -2.0)
    x0 = initial_state(0.1, 0.5, 1.0, -1.5, p)
    t_eval = np.arange(0, 501) * 1e-3
    ref = solve_ivp(lambda t, y: f(t, tuple(y), u, p, dist(t)), (0.0, 0.5), x0, method="DOP853",
                    rtol=1e-10, atol=1e-12, t_eval=t_eval).y.T
    err = np.abs(_rk4_path(x0, u, dist, p, 1e-3, 2, 0.5) - ref)
    assert np.abs(ref[:, 0:2] - ref[0, 0:2]).max() > 0.3  # the limb really moves
    assert err[:, 0:2].max() < 1e-7
    assert err[:, 2:4].max() < 3e-5
    assert err[:, 4:6].max() < 1e-11
    assert err[:, 6:8].max() < 5e-10
    fine = np.abs(_rk4_path(x0, u, dist, p, 1e-3, 4, 0.5) - ref)
    assert 12.0 < err[:, 0:2].max() / fine[:, 0:2].max() < 20.0


@pytest.mark.parametrize("q", [(0.0, 0.0), (0.3, 0.9), (-0.3, 0.2), (0.05, 0.55)])
def test_initial_state_is_a_static_equilibrium(p: LimbParams, q: tuple[float, float]) -> None:
    x = initial_state(q[0], q[1], 0.0, 0.0, p)
    dx = f(0.0, x, (0.0, 0.0), p)
    assert max(abs(v) for v in dx) < 1e-9
    if q[0] != 0.0:  # away from hanging straight down, the springs really hold gravity
        assert abs(deflections(x, p)[0]) > 1e-5
    x_end = advance(0.0, x, (0.0, 0.0), 0.1, 200, p)
    assert max(abs(a - b) for a, b in zip(x, x_end, strict=True)) < 1e-9


def test_deflections_follow_eq7(p: LimbParams) -> None:
    x = _random_states(1, 4, p)[0]
    len1, len2 = sea_lengths(x[0], x[1], p)
    d1, d2, dd1, dd2 = deflections(x, p)
    assert (d1, d2) == pytest.approx((len1 - p.l_ref[0] - x[4], len2 - p.l_ref[1] - x[5]), abs=1e-15)
    h = 1e-7  # Delta_dot is the time derivative along the state's motion
    xp = tuple(a + h * b for a, b in zip(x, f(0.0, x, (0.0, 0.0), p), strict=True))
    assert dd1 == pytest.approx((deflections(xp, p)[0] - d1) / h, rel=1e-4)
    assert dd2 == pytest.approx((deflections(xp, p)[1] - d2) / h, rel=1e-4)


def test_saturate_and_is_finite() -> None:
    assert saturate(30.0, 24.0) == 24.0 and saturate(-30.0, 24.0) == -24.0 and saturate(3.5, 24.0) == 3.5
    assert saturate(float("nan"), 24.0) == 0.0
    assert is_finite((0.0,) * 8) and not is_finite((0.0,) * 7 + (float("inf"),))


@pytest.mark.parametrize("kind", ["constant", "sine", "noise"])
def test_disturbance_is_bounded_by_amplitude(kind: str) -> None:
    amp = (1.5, 0.4)
    dist = make_disturbance(DisturbanceConfig(kind=kind, amplitude_nm=amp, frequency_hz=2.0, seed=5))
    vals = np.array([dist(t) for t in np.linspace(0.0, 3.0, 3001)])
    assert np.all(np.abs(vals[:, 0]) <= amp[0]) and np.all(np.abs(vals[:, 1]) <= amp[1])
    assert np.abs(vals[:, 0]).max() > 0.9 * amp[0]  # and it uses its range


def test_disturbance_none_is_zero() -> None:
    assert make_disturbance(DisturbanceConfig(kind="none", amplitude_nm=(3.0, 3.0)))(1.0) == (0.0, 0.0)
    assert make_disturbance(DisturbanceConfig(kind="sine"))(0.3) == (0.0, 0.0)


def test_noise_is_seeded_held_and_reproducible() -> None:
    def trace(seed: int) -> list[tuple[float, float]]:
        dist = make_disturbance(DisturbanceConfig(kind="noise", amplitude_nm=(1.0, 1.0), noise_hold_s=0.01, seed=seed))
        return [dist(t) for t in np.arange(0, 200) * 0.0025]

    a, b, c = trace(1), trace(1), trace(2)
    assert a == b
    assert a != c
    assert a[0] == a[1] == a[2] == a[3] and a[3] != a[4]  # held for 10 ms (4 samples of 2.5 ms)
    # value depends only on (seed, t): querying out of order gives the same answer
    dist = make_disturbance(DisturbanceConfig(kind="noise", amplitude_nm=(1.0, 1.0), noise_hold_s=0.01, seed=1))
    assert [dist(t) for t in (np.arange(0, 200) * 0.0025)[::-1]][::-1] == a
