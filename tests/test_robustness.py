"""Issue 15: bounded disturbances and model mismatch, offline (default trajectory, one 10 s cycle, CAN quantisation).

Bounds are the issue's acceptance: max tracking error <= 0.01 rad for TT and ET, <= 1 % of inner steps saturated,
under a constant disturbance ET sends <= 0.40 of TT's setpoints (docs/deviations.md section 10)."""
from __future__ import annotations

import numpy as np
import pytest

from sea_hil.config.loader import load_config
from sea_hil.config.shorthand import scenario_config
from sea_hil.controller.backstepping import InnerGains, backstepping_voltage
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.observer import OBSERVER_UNSTARTED, observer_step
from sea_hil.dynamics import deflections, initial_state
from sea_hil.mechanics import limb_params, sea_geometry
from sea_hil.offline.closed_loop import SimResult, simulate
from sea_hil.plant_emulator.integrator import rk4_step

BOUND_RAD = 0.01
HIP, KNEE = "hip=", "knee="


def _sim(disturbance: str | None = None, mismatch: str | None = None, mode: str = "tt", **ov: dict) -> SimResult:
    return simulate(scenario_config(None, ov, disturbance, mismatch), mode, quantise=True)


def _max_err(r: SimResult) -> float:
    return float(np.abs(r.theta_rad - r.desired_rad).max())


def _saturated(r: SimResult) -> float:
    return r.saturated_steps / r.inner_steps


def _check(spec: str | None, mismatch: str | None = None, bound: float = BOUND_RAD) -> dict[str, SimResult]:
    runs = {m: _sim(spec, mismatch, m) for m in ("tt", "et")}
    for m, r in runs.items():
        assert _max_err(r) <= bound, (spec, mismatch, m, _max_err(r))
        assert _saturated(r) <= 0.01, (spec, mismatch, m, _saturated(r))
    return runs


@pytest.mark.parametrize("joints", [(KNEE,), (HIP,), (HIP, KNEE)], ids=["knee", "hip", "both"])
@pytest.mark.parametrize("kind", ["constant:{a}Nm", "sine:{a}Nm@0.5Hz", "sine:{a}Nm@2Hz", "noise:{a}Nm@10ms"])
def test_disturbances_within_the_design_bound_are_rejected(kind: str, joints: tuple[str, ...]) -> None:
    spec = ",".join(j + kind.format(a=0.5 if j == HIP else 0.05) for j in joints)
    runs = _check(spec)
    if kind.startswith("constant"):  # events only while the error moves: no degradation to TT
        assert len(runs["et"].event_t_s) <= 0.40 * len(runs["tt"].event_t_s)


def test_the_compensating_deflection_rate_enters_eq27_and_its_derivative() -> None:
    """'full': c = d_hat / (k a) is not held, so Eq. 27 gets c' (through kp2 in Eq. 31) and v1' gets kp1 c':
    at rest, a torque rate r changes the voltage by -(kp1 + kp2) r / (k a); 'inner' and 'off' ignore it."""
    p = limb_params(load_config().plant)
    m = (0.05, 0.5, 0.0, 0.0, 1e-4, 2e-4, 0.0, 0.0)
    _, _, a1, a2, _, _ = sea_geometry(0.05, 0.5, p)
    for comp, expect in ((2, 1.0), (1, 0.0), (0, 0.0)):
        gains = InnerGains(60.0, 100.0, 0.0, comp, 400.0)
        base = backstepping_voltage(m, (1e-4, 1e-4), (0.0, 0.0), p, gains, (0.1, 0.01, 0.0, 0.0))
        rate = backstepping_voltage(m, (1e-4, 1e-4), (0.0, 0.0), p, gains, (0.1, 0.01, 3.0, -0.5))
        assert rate[0] - base[0] == pytest.approx(-expect * 160.0 * 3.0 / (p.k1 * a1), rel=1e-9, abs=1e-12)
        assert rate[1] - base[1] == pytest.approx(expect * 160.0 * 0.5 / (p.k2 * a2), rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("group", ["mass", "inertia", "stiffness"])
@pytest.mark.parametrize("sign", ["+", "-"])
def test_twenty_percent_model_mismatch_still_tracks(group: str, sign: str) -> None:
    _check(None, f"{group}={sign}20%")


def test_mass_and_stiffness_mismatch_tracks_and_the_nominal_model_differs() -> None:
    """Issue 12's test: controller's masses +20 %, spring constants -20 % (ET: max error 0.0040 rad)."""
    cfg = scenario_config(None, {}, None, "mass=+20%,stiffness=-20%")
    pn, p = nominal_params(cfg), limb_params(cfg.plant)
    assert pn.m1 == pytest.approx(1.2 * p.m1) and pn.k2 == pytest.approx(0.8 * p.k2) and pn.i1 == p.i1
    _check(None, "mass=+20%,stiffness=-20%")


def test_the_paper_path_shows_the_fault() -> None:
    """disturbance_compensation = "off" is the paper's inner loop (bit for bit against the pre-issue results:
    tests/test_pre_refactor_equality.py, through tests/fixtures/pre_refactor/paper_path.toml); it has the fault."""
    off = {"controller": {"disturbance_compensation": "off"}}
    r = _sim("knee=constant:0.05Nm", mode="tt", **off)
    assert _max_err(r) > 0.3  # the unobserved disturbance: 0.49 rad


def test_observer_recovers_a_constant_torque_and_a_model_error() -> None:
    """Open loop, constant voltage: d_hat converges to the true disturbance plus what the nominal model lacks."""
    cfg = load_config(overrides={"controller": {"model": {"m2_kg": 0.89 * 1.1}}})
    p, pn = limb_params(cfg.plant), nominal_params(cfg)
    x = initial_state(0.05, 0.5, 0.0, 0.0, p)
    d = (0.2, -0.05)
    obs = OBSERVER_UNSTARTED
    for k in range(300):
        dl = deflections(x, p)
        obs, _ = observer_step((x[0], x[1], x[2], x[3], dl[0], dl[1], x[6], x[7]), obs, pn, 400.0, 1e-3)
        for i in range(2):
            x = rk4_step(k * 1e-3 + i * 5e-4, x, (0.3, -0.2), 5e-4, p, lambda t: d)
    # lumped torque: d + (what the nominal model predicts) - (what the plant does) = d + (M_n - M) qdd + N - N_n
    exact = load_config()
    obs_exact = OBSERVER_UNSTARTED
    x = initial_state(0.05, 0.5, 0.0, 0.0, p)
    for k in range(300):
        dl = deflections(x, p)
        obs_exact, _ = observer_step((x[0], x[1], x[2], x[3], dl[0], dl[1], x[6], x[7]), obs_exact,
                                     limb_params(exact.plant), 400.0, 1e-3)
        for i in range(2):
            x = rk4_step(k * 1e-3 + i * 5e-4, x, (0.3, -0.2), 5e-4, p, lambda t: d)
    assert obs_exact[2:4] == pytest.approx(d, abs=2e-3)
    assert abs(obs[3] - d[1]) > 5e-3  # the 10 % heavier nominal shank shows up in the lumped estimate


def test_observer_follows_a_2hz_torque_at_the_measurement_time() -> None:
    """Open loop, 0.5 N m at 2 Hz on the hip: the estimate for the measurement's own time has a small error (third
    order: no ramp lag), and its rate follows d'; the updated state (which belongs one period later) is the
    estimate the earlier design applied, a period early."""
    cfg = load_config()
    p = limb_params(cfg.plant)
    x = initial_state(0.05, 0.5, 0.0, 0.0, p)
    w = 4.0 * np.pi
    obs, errs, rate_errs, ahead_errs = OBSERVER_UNSTARTED, [], [], []
    for k in range(1000):
        t = k * 1e-3
        dl = deflections(x, p)
        obs, est = observer_step((x[0], x[1], x[2], x[3], dl[0], dl[1], x[6], x[7]), obs, p, 400.0, 1e-3)
        if k >= 200:
            errs.append(abs(est[0] - 0.5 * np.sin(w * t)))
            rate_errs.append(abs(est[2] - 0.5 * w * np.cos(w * t)))
            ahead_errs.append(abs(obs[2] - 0.5 * np.sin(w * t)))
        for i in range(2):
            x = rk4_step(t + i * 5e-4, x, (0.0, 0.0), 5e-4, p, lambda tt: (0.5 * np.sin(w * tt), 0.0))
    assert max(errs) < 0.004                      # measured 0.0032 N m (0.6 % of the amplitude)
    assert max(ahead_errs) > 2.0 * max(errs)      # measured 0.0071 N m: the updated state is for t + 1 ms
    assert max(rate_errs) < 0.15 * 0.5 * w        # measured 0.59 N m/s (9 % of 6.3)
