"""Limb geometry and mass matrix (paper Eq. 1, 2, 4, 8) checked against independent computations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sea_hil.config.loader import load_config
from sea_hil.controller.trajectory import GaitTrajectory
from sea_hil.mechanics import (
    LimbParams,
    fx_gx,
    limb_params,
    mass_matrix,
    n_terms,
    sea_geometry,
    sea_lengths,
    sea_lengths_expanded,
    solve_m,
)

GRID = np.linspace(-1.5, 1.5, 31)


@pytest.fixture(scope="module")
def p() -> LimbParams:
    return limb_params(load_config().plant)


def _gait_range() -> tuple[tuple[float, float], tuple[float, float]]:
    traj = GaitTrajectory(10.0)
    q = np.array([traj.sample(t).theta_rad for t in np.linspace(0.0, 10.0, 2001)])
    return (float(q[:, 0].min()), float(q[:, 0].max())), (float(q[:, 1].min()), float(q[:, 1].max()))


def _max_diff_between_forms(p: LimbParams) -> float:
    worst = 0.0
    for q1 in GRID:
        for q2 in GRID:
            a = sea_lengths(q1, q2, p)
            b = sea_lengths_expanded(q1, q2, p)
            worst = max(worst, abs(a[0] - b[0]), abs(a[1] - b[1]))
    return worst


def test_sigma_is_atan2_of_the_link_offsets(p: LimbParams) -> None:
    d = p.d
    assert p.sigma1 == pytest.approx(math.atan2(d[1], d[0]), abs=1e-15)
    assert p.sigma2 == pytest.approx(math.atan2(d[6], d[5]), abs=1e-15)


def _consistent(p: LimbParams) -> LimbParams:
    """The paper's d's are rounded to mm: d3 = |(d1, d2)| and d8 = |(d6, d7)| hold only to ~0.1 mm; make them exact."""
    d = list(p.d)
    d[2], d[7] = math.hypot(d[0], d[1]), math.hypot(d[5], d[6])
    return p._replace(d=tuple(d))


def test_both_forms_of_eq1_agree_over_a_grid(p: LimbParams) -> None:
    assert _max_diff_between_forms(_consistent(p)) < 1e-12
    # with the paper's rounded dimensions they agree to the rounding (d3, d8 are off by 0.08 mm and 0.01 mm)
    assert _max_diff_between_forms(p) < 1e-3


@pytest.mark.parametrize("which", ["swapped", "zero", "shifted"])
def test_both_forms_of_eq1_disagree_for_other_sigmas(p: LimbParams, which: str) -> None:
    d = p.d
    sig = {"swapped": (math.atan2(d[0], d[1]), math.atan2(d[5], d[6])),
           "zero": (0.0, 0.0),
           "shifted": (p.sigma1 + 0.05, p.sigma2 - 0.05)}[which]
    assert _max_diff_between_forms(_consistent(p)._replace(sigma1=sig[0], sigma2=sig[1])) > 4e-3


def test_lengths_at_reference_angles_define_l_ref(p: LimbParams) -> None:
    assert p.l_ref == sea_lengths(p.theta_ref[0], p.theta_ref[1], p)


def test_moment_arms_and_their_derivatives_match_finite_differences(p: LimbParams) -> None:
    h = 1e-6
    for q1 in GRID[::3]:
        for q2 in GRID[::3]:
            len1, len2, a1, a2, a1p, a2p = sea_geometry(q1, q2, p)
            assert (len1, len2) == pytest.approx(sea_lengths(q1, q2, p), abs=1e-15)
            lp, lm = sea_lengths(q1 + h, q2 + h, p), sea_lengths(q1 - h, q2 - h, p)
            # L1 depends on q1 only and L2 on q2 only, so one diagonal step differentiates both
            assert a1 == pytest.approx((lp[0] - lm[0]) / (2 * h), abs=1e-8)
            assert a2 == pytest.approx((lp[1] - lm[1]) / (2 * h), abs=1e-8)
            gp, gm = sea_geometry(q1 + h, q2 + h, p), sea_geometry(q1 - h, q2 - h, p)
            assert a1p == pytest.approx((gp[2] - gm[2]) / (2 * h), abs=1e-7)
            assert a2p == pytest.approx((gp[3] - gm[3]) / (2 * h), abs=1e-7)
            # cross-dependence really is absent
            assert sea_lengths(q1, q2 + 0.3, p)[0] == sea_lengths(q1, q2, p)[0]
            assert sea_lengths(q1 + 0.3, q2, p)[1] == sea_lengths(q1, q2, p)[1]


def _gamma(opposite: float, adjacent: float, length: float) -> float:
    """Triangle angle between side `adjacent` and the SEA (law of cosines), opposite side `opposite`."""
    return math.acos((adjacent ** 2 + length ** 2 - opposite ** 2) / (2.0 * adjacent * length))


def test_moment_arm_equals_d_sin_gamma_from_the_triangle(p: LimbParams) -> None:
    """Eq. 4: a1 = d4 sin(gamma1), a2 = d9 sin(gamma2); gamma by the law of cosines on (d3, d4, L_S1), (d8, d9, L_S2)."""
    d3, d4, d8, d9 = p.d[2], p.d[3], p.d[7], p.d[8]
    (h0, h1), (k0, k1) = _gait_range()
    for q1 in np.linspace(h0, h1, 15):
        for q2 in np.linspace(k0, k1, 15):
            len1, len2 = sea_lengths(q1, q2, p)  # the triangle's third side
            _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
            g1, g2 = _gamma(d3, d4, len1), _gamma(d8, d9, len2)
            assert a1 == pytest.approx(d4 * math.sin(g1), rel=1e-9)
            assert a2 == pytest.approx(d9 * math.sin(g2), rel=1e-9)
            # law of sines: sin(gamma1) / d3 == sin(beta1) / L_S1, beta1 the apex angle at O1 (law of cosines)
            beta1 = math.acos((d3**2 + d4**2 - len1**2) / (2 * d3 * d4))
            assert math.sin(g1) / d3 == pytest.approx(math.sin(beta1) / len1, rel=1e-9)


def test_moment_arms_stay_far_from_zero_over_the_gait(p: LimbParams) -> None:
    """|a| > 0.5 * (max over all angles) on the default gait's joint range (g_x stays invertible)."""
    beta = np.linspace(0.0, 2 * math.pi, 4001)
    max1 = max(abs(sea_geometry(b, 0.0, p)[2]) for b in beta)
    max2 = max(abs(sea_geometry(0.0, b, p)[3]) for b in beta)
    # the geometric maximum is the shorter triangle side (distance from the pivot to the SEA line)
    assert max1 == pytest.approx(min(p.d[2], p.d[3]), rel=1e-3)
    assert max2 == pytest.approx(min(p.d[7], p.d[8]), rel=1e-3)
    (h0, h1), (k0, k1) = _gait_range()
    assert h1 - h0 > 0.5 and k1 - k0 > 0.5  # the gait really sweeps a range
    for q1 in np.linspace(h0, h1, 41):
        assert abs(sea_geometry(q1, 0.5, p)[2]) > 0.5 * max1
    for q2 in np.linspace(k0, k1, 41):
        assert abs(sea_geometry(0.05, q2, p)[3]) > 0.5 * max2


def test_mass_matrix_symmetric_positive_definite(p: LimbParams) -> None:
    for q2 in np.linspace(-math.pi, math.pi, 73):
        m11, m12, m22 = mass_matrix(q2, p)
        m = np.array([[m11, -m12], [-m12, m22]])
        assert np.array_equal(m, m.T)
        assert np.linalg.eigvalsh(m).min() > 1e-4


def test_mass_matrix_without_i2_coupling_is_eq2_literally() -> None:
    cfg = load_config(overrides={"plant": {"include_i2_in_coupling": False}}).plant
    p = limb_params(cfg)
    m1, m2, r1, r2, l1, i1, i2 = cfg.m1_kg, cfg.m2_kg, cfg.r1_m, cfg.r2_m, cfg.l1_m, cfg.i1_kgm2, cfg.i2_kgm2
    for q2 in np.linspace(-2.0, 2.0, 17):
        m11, m12, m22 = mass_matrix(q2, p)
        eq2_m11 = m1 * r1**2 + i1 + m2 * l1**2 + m2 * r2**2 + 2 * m2 * l1 * r2 * math.cos(q2)
        assert m11 == pytest.approx(eq2_m11, rel=1e-14)
        assert m12 == pytest.approx(m2 * r2**2 + m2 * l1 * r2 * math.cos(q2), rel=1e-14)
        assert m22 == pytest.approx(m2 * r2**2 + i2, rel=1e-14)
    # the default (Lagrangian) form adds I2 to M11 and M12 and differs measurably
    d11, d12, _ = mass_matrix(0.3, limb_params(load_config().plant))
    l11, l12, _ = mass_matrix(0.3, p)
    assert d11 - l11 == pytest.approx(i2) and d12 - l12 == pytest.approx(i2)


def test_solve_m_and_fx_gx_match_numpy(p: LimbParams) -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        q1, q2, w1, w2 = rng.uniform(-1, 1, 4)
        m11, m12, m22 = mass_matrix(q2, p)
        m = np.array([[m11, -m12], [-m12, m22]])
        y = rng.normal(size=2)
        assert solve_m(m11, m12, m22, *y) == pytest.approx(tuple(np.linalg.solve(m, y)), rel=1e-10)
        _, _, a1, a2, _, _ = sea_geometry(q1, q2, p)
        f1, f2, g = fx_gx(q1, q2, w1, w2, a1, a2, p)
        n = np.array(n_terms(q1, q2, w1, w2, p))
        assert (f1, f2) == pytest.approx(tuple(np.linalg.solve(m, n)), rel=1e-10)
        gx = np.linalg.solve(m, np.diag([-p.k1 * a1, -p.k2 * a2]))
        assert g == pytest.approx(tuple(gx.ravel()), rel=1e-10)
