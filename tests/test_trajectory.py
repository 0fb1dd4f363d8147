"""Desired trajectories: the built-in gait and CSV files (good and bad)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sea_hil.config.model import TrajectoryConfig
from sea_hil.controller.trajectory import CsvTrajectory, GaitTrajectory, LeadIn, make_trajectory
from sea_hil.errors import TrajectoryError


def _fd(fn, t: float, h: float) -> tuple[float, float]:
    return tuple((a - b) / (2 * h) for a, b in zip(fn(t + h), fn(t - h), strict=True))  # type: ignore[return-value]


def test_gait_derivatives_match_finite_differences() -> None:
    g = GaitTrajectory(10.0)
    h = 1e-5
    for t in np.linspace(0.0, 10.0, 37):
        s = g.sample(t)
        assert s.omega_rad_s == pytest.approx(_fd(lambda x: g.sample(x).theta_rad, t, h), abs=1e-8)
        assert s.alpha_rad_s2 == pytest.approx(_fd(lambda x: g.sample(x).omega_rad_s, t, h), abs=1e-8)


def test_gait_is_periodic_with_its_period() -> None:
    g = GaitTrajectory(10.0)
    for t in np.linspace(0.0, 10.0, 23):
        a, b = g.sample(t), g.sample(t + 10.0)
        for x, y in ((a.theta_rad, b.theta_rad), (a.omega_rad_s, b.omega_rad_s), (a.alpha_rad_s2, b.alpha_rad_s2)):
            assert x == pytest.approx(y, abs=1e-12)
    # not periodic with a shorter period (the harmonics really have period 10 s)
    assert g.sample(1.0).theta_rad != pytest.approx(g.sample(6.0).theta_rad, abs=1e-3)
    assert make_trajectory(TrajectoryConfig()).period_s == 10.0


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _sine_csv(path: Path, n: int = 201, period_s: float = 2.0) -> Path:
    t = np.linspace(0.0, period_s, n)
    w = 2 * math.pi / period_s
    rows = "\n".join(f"{float(a)!r},{0.3 * math.sin(w * a)!r},{0.5 + 0.2 * math.cos(w * a)!r}" for a in t)
    return _write(path, "t,theta1,theta2\n" + rows + "\n")


def test_csv_round_trips_values_at_knots(tmp_path: Path) -> None:
    text = "t, theta1, theta2\n0,0.1,0.5\n0.5,0.2,0.4\n1.0,0.05,0.7\n1.7,-0.1,0.6\n2.0,0.0,0.3\n"
    path = _write(tmp_path / "k.csv", text)  # spaces in the header are accepted
    tr = CsvTrajectory(path)
    for t, a, b in ((0, 0.1, 0.5), (0.5, 0.2, 0.4), (1.0, 0.05, 0.7), (1.7, -0.1, 0.6), (2.0, 0.0, 0.3)):
        assert tr.sample(t).theta_rad == pytest.approx((a, b), abs=1e-12)
    assert tr.period_s == 2.0
    # not periodic (first row != last row): held at the ends
    assert tr.sample(5.0).theta_rad == pytest.approx((0.0, 0.3), abs=1e-12)
    assert tr.sample(-1.0).theta_rad == pytest.approx((0.1, 0.5), abs=1e-12)


def test_csv_sine_derivatives_are_close_to_analytic(tmp_path: Path) -> None:
    tr = CsvTrajectory(_sine_csv(tmp_path / "sine.csv"))
    w = 2 * math.pi / 2.0
    for t in np.linspace(0.0, 4.0, 41):  # also past the end: first row == last row -> periodic
        s = tr.sample(t)
        assert s.theta_rad == pytest.approx((0.3 * math.sin(w * t), 0.5 + 0.2 * math.cos(w * t)), abs=1e-6)
        assert s.omega_rad_s == pytest.approx((0.3 * w * math.cos(w * t), -0.2 * w * math.sin(w * t)), abs=1e-4)
        assert s.alpha_rad_s2 == pytest.approx((-0.3 * w * w * math.sin(w * t), -0.2 * w * w * math.cos(w * t)),
                                               abs=1e-2)


def test_make_trajectory_reads_csv_from_config(tmp_path: Path) -> None:
    path = _sine_csv(tmp_path / "s.csv")
    tr = make_trajectory(TrajectoryConfig(kind="csv", csv_path=str(path)))
    assert isinstance(tr, CsvTrajectory) and tr.period_s == pytest.approx(2.0)
    with pytest.raises(TrajectoryError, match="csv_path"):
        make_trajectory(TrajectoryConfig(kind="csv"))


GOOD_ROWS = "0,0,0\n1,0.1,0.1\n2,0.2,0.2\n3,0.1,0.3\n"

BAD = {
    "missing_column": ("t,theta1\n0,0\n1,0.1\n2,0.2\n3,0.3\n", r"missing column.*theta2"),
    "nan": ("t,theta1,theta2\n0,0,0\n1,nan,0.1\n2,0.2,0.2\n3,0.1,0.3\n", r"NaN or infinite value on line 3"),
    "inf": ("t,theta1,theta2\n" + GOOD_ROWS + "4,0,inf\n", r"NaN or infinite value on line 6"),
    "non_monotonic": ("t,theta1,theta2\n0,0,0\n1,0.1,0.1\n1,0.2,0.2\n3,0.1,0.3\n",
                      r"not strictly increasing \(line 4\)"),
    "decreasing": ("t,theta1,theta2\n0,0,0\n2,0.1,0.1\n1,0.2,0.2\n3,0.1,0.3\n", r"not strictly increasing"),
    "non_numeric": ("t,theta1,theta2\n0,0,0\n1,abc,0.1\n2,0.2,0.2\n3,0.1,0.3\n", r"non-numeric value"),
    "empty_cell": ("t,theta1,theta2\n0,0,0\n1,,0.1\n2,0.2,0.2\n3,0.1,0.3\n", r"non-numeric value"),
    "short_row": ("t,theta1,theta2\n0,0,0\n1,0.1\n2,0.2,0.2\n3,0.1,0.3\n", r"non-numeric value"),
    "too_few_rows": ("t,theta1,theta2\n0,0,0\n1,0.1,0.1\n2,0.2,0.2\n", r"at least 4 rows, got 3"),
    "empty_file": ("", r"missing column"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_csv_raises_trajectory_error(tmp_path: Path, name: str) -> None:
    text, pattern = BAD[name]
    path = _write(tmp_path / f"{name}.csv", text)
    with pytest.raises(TrajectoryError, match=pattern) as info:
        CsvTrajectory(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg


def test_missing_file_raises_trajectory_error(tmp_path: Path) -> None:
    with pytest.raises(TrajectoryError, match=r"cannot read trajectory .*nope\.csv"):
        CsvTrajectory(tmp_path / "nope.csv")


def test_unreadable_file_raises_trajectory_error(tmp_path: Path) -> None:
    binary = tmp_path / "latin1.csv"
    binary.write_bytes(b"t,theta1,theta2\n0,0,0\n\xff\xfe,1,1\n")
    with pytest.raises(TrajectoryError, match="cannot read trajectory"):
        CsvTrajectory(binary)
    with pytest.raises(TrajectoryError, match="cannot read trajectory"):
        CsvTrajectory(tmp_path)  # a directory


def test_good_rows_fixture_is_accepted(tmp_path: Path) -> None:
    """The bad cases above differ from an accepted file only in the broken part."""
    tr = CsvTrajectory(_write(tmp_path / "ok.csv", "t,theta1,theta2\n" + GOOD_ROWS))
    assert tr.sample(1.0).theta_rad == pytest.approx((0.1, 0.1))


def test_lead_in_joins_rest_to_the_trajectory_start_smoothly() -> None:
    target = GaitTrajectory(10.0).sample(0.0)
    start_theta, start_omega = (0.04, 0.30), (0.0, 0.01)
    lead = LeadIn(start_theta, start_omega, target, 0.5)
    first, last = lead.sample(-0.5), lead.sample(0.0)
    assert first.theta_rad == pytest.approx(start_theta, abs=1e-12)
    assert first.omega_rad_s == pytest.approx(start_omega, abs=1e-12)
    assert first.alpha_rad_s2 == pytest.approx((0.0, 0.0), abs=1e-9)
    for got, want in ((last.theta_rad, target.theta_rad), (last.omega_rad_s, target.omega_rad_s),
                      (last.alpha_rad_s2, target.alpha_rad_s2)):
        assert got == pytest.approx(want, abs=1e-9)
    h = 1e-6                      # derivatives are the polynomial's own
    for t in (-0.4, -0.25, -0.1):
        a, b, m = lead.sample(t - h), lead.sample(t + h), lead.sample(t)
        for j in (0, 1):
            assert (b.theta_rad[j] - a.theta_rad[j]) / (2 * h) == pytest.approx(m.omega_rad_s[j], abs=1e-6)
            assert (b.omega_rad_s[j] - a.omega_rad_s[j]) / (2 * h) == pytest.approx(m.alpha_rad_s2[j], abs=1e-5)
    assert lead.sample(-3.0) == first and lead.sample(1.0) == last   # clamped outside [-T, 0]


def test_lead_in_needs_a_positive_duration() -> None:
    with pytest.raises(TrajectoryError, match="lead-in"):
        LeadIn((0.0, 0.0), (0.0, 0.0), GaitTrajectory(10.0).sample(0.0), 0.0)
