"""`--disturbance` / `--mismatch` shorthands, per-joint [disturbance] tables, [controller.model] round trips."""
from __future__ import annotations

import tomllib

import pytest

from sea_hil.config.loader import config_from_dict, config_to_toml, load_config
from sea_hil.config.model import DisturbanceConfig
from sea_hil.config.shorthand import disturbance_overrides, mismatch_factors, scenario_config
from sea_hil.errors import ConfigError
from sea_hil.plant_emulator.disturbance import make_disturbance


def test_disturbance_spec_per_joint_and_for_both() -> None:
    assert disturbance_overrides("knee=sine:0.05Nm@2Hz,hip=constant:0.5Nm") == {
        "knee": {"kind": "sine", "amplitude_nm": 0.05, "frequency_hz": 2.0},
        "hip": {"kind": "constant", "amplitude_nm": 0.5}}
    both = disturbance_overrides("noise:0.05@10ms")
    assert both["hip"] == both["knee"] == {"kind": "noise", "amplitude_nm": 0.05, "noise_hold_s": 0.01}
    assert disturbance_overrides("hip=none") == {"hip": {"kind": "none"}}


@pytest.mark.parametrize("spec", ["knee=sine:0.05Nm", "ankle=constant:1", "knee=wobble:1", "constant:1Nm@2Hz",
                                  "knee=constant:abc", "knee=constant:1,knee=constant:2", "sine:1@10ms", ""])
def test_bad_disturbance_specs_are_config_errors(spec: str) -> None:
    with pytest.raises(ConfigError, match="--disturbance"):
        disturbance_overrides(spec)


def test_mismatch_spec_groups_and_parameters() -> None:
    assert mismatch_factors("mass=+20%,k2=-10%") == pytest.approx({"m1_kg": 1.2, "m2_kg": 1.2, "k2_n_per_m": 0.9})
    cfg = scenario_config(None, {}, None, "stiffness=-20%")
    assert cfg.controller.model.k1_n_per_m == pytest.approx(0.8 * cfg.plant.k1_n_per_m)
    assert cfg.controller.model.m1_kg is None


@pytest.mark.parametrize("spec", ["mass=20", "mass=-100%", "weight=+5%", "mass=+1%,m1=+2%"])
def test_bad_mismatch_specs_are_config_errors(spec: str) -> None:
    with pytest.raises(ConfigError, match="--mismatch"):
        mismatch_factors(spec)


@pytest.mark.parametrize("kind", ["constant", "sine", "noise"])
def test_the_flat_form_is_the_same_torque_as_two_joint_tables(kind: str) -> None:
    flat = DisturbanceConfig(kind=kind, amplitude_nm=(0.4, 0.07), frequency_hz=1.3, noise_hold_s=0.02, seed=3)
    joints = DisturbanceConfig(seed=3, **{j: {"kind": kind, "amplitude_nm": a, "frequency_hz": 1.3,
                                              "noise_hold_s": 0.02} for j, a in (("hip", 0.4), ("knee", 0.07))})
    d_flat, d_joint = make_disturbance(flat), make_disturbance(joints)
    values = [d_flat(0.001 * k) for k in range(200)]
    assert values == [d_joint(0.001 * k) for k in range(200)]
    assert len(set(values)) > 1 or kind == "constant"


def test_a_joint_table_replaces_only_its_joint() -> None:
    cfg = DisturbanceConfig(kind="constant", amplitude_nm=(0.3, 0.1), knee={"kind": "sine", "amplitude_nm": 0.05})
    d = make_disturbance(cfg)
    assert d(0.5)[0] == 0.3 and abs(d(0.5)[1]) <= 0.05 and d(0.5)[1] != 0.1
    assert DisturbanceConfig(hip={"kind": "constant", "amplitude_nm": 0.0}).is_zero()


def test_scenario_config_round_trips_through_toml() -> None:
    cfg = scenario_config(None, {}, "knee=sine:0.05Nm@2Hz", "inertia=-20%")
    again = config_from_dict(tomllib.loads(config_to_toml(cfg)))
    assert again == cfg
    assert load_config() == config_from_dict(tomllib.loads(config_to_toml(load_config())))


def test_sweep_points_carry_the_scenario(tmp_path) -> None:
    from sea_hil.sweep.grid import expand_grid
    from sea_hil.sweep.runner import SweepOptions, point_config
    point = expand_grid([0.5], [0.2], [0.0], [0.0], [0.0])[0]
    opts = SweepOptions(out=tmp_path, mode="offline", disturbance="knee=constant:0.05Nm", mismatch="stiffness=+10%")
    cfg = point_config(opts, point)
    assert cfg.disturbance.knee is not None and cfg.disturbance.knee.amplitude_nm == 0.05
    assert cfg.controller.model.k2_n_per_m == pytest.approx(1.1 * cfg.plant.k2_n_per_m)


def test_robustness_grid_and_outputs(tmp_path) -> None:
    from sea_hil.offline.robustness import grid, run_grid
    from sea_hil.offline.robustness_output import write_csv, write_figure, write_markdown
    points = grid((0.0, 1.0), (20.0,))
    assert len(points) == 4 * 2 + 3 and points[1].disturbance == "hip=constant:0.5Nm,knee=constant:0.05Nm"
    assert points[-1].mismatch == "stiffness=+20%"
    rows = run_grid([points[1], points[-1]], None, {"trajectory": {"period_s": 2.0}}, 0.5, log=lambda s: None)
    assert [(r["axis"], r["controller"]) for r in rows] == [("disturbance", "tt"), ("disturbance", "et"),
                                                           ("mismatch", "tt"), ("mismatch", "et")]
    assert rows[0]["transmissions"] == 200 and 0 < rows[1]["transmissions"] < 200
    write_csv(tmp_path / "r.csv", rows)
    write_figure(tmp_path / "r.png", rows)
    write_markdown(tmp_path / "r.md", rows, "sea-hil robustness")
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    assert len((tmp_path / "r.csv").read_text().splitlines()) == 5
    assert "| mismatch | stiffness | +20 % |" in (tmp_path / "r.md").read_text()
