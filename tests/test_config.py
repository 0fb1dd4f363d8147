"""Frozen TOML configuration: defaults, overlays, and one-line ConfigError for every kind of bad input."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pydantic
import pytest

from sea_hil.config.loader import config_from_dict, config_to_toml, default_toml_text, load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError, SeaHilError

REPO = Path(__file__).resolve().parent.parent


def _write(tmp_path: Path, text: str, name: str = "user.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_defaults_load_and_match_the_embedded_toml() -> None:
    cfg = load_config()
    raw = tomllib.loads(default_toml_text())
    assert cfg.plant.d_m == tuple(raw["plant"]["d_m"])
    assert cfg.plant.k1_n_per_m == raw["plant"]["k1_n_per_m"] == 20000.0
    assert (cfg.controller.c, cfg.controller.rho) == (raw["controller"]["c"], raw["controller"]["rho"])
    assert (cfg.trigger.r, cfg.trigger.eta, cfg.trigger.lipschitz_l) == (0.2, 0.5, 0.85)
    assert cfg.trajectory.kind == "gait" and cfg.trajectory.period_s == 10.0
    assert cfg.disturbance.kind == "none"
    assert cfg.link.uplink.loss == 0.0


def test_config_is_frozen() -> None:
    cfg = load_config()
    with pytest.raises(pydantic.ValidationError):
        cfg.controller.c = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("text, where", [
    ("[plant]\nfoo_m = 1.0\n", "plant.foo_m"),
    ("[bogus]\nx = 1\n", "bogus"),
    ("[link.uplink]\ndelay = 0.1\n", "link.uplink.delay"),
])
def test_unknown_key_is_a_one_line_config_error(tmp_path: Path, text: str, where: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, text))
    msg = str(info.value)
    assert where in msg and "\n" not in msg


@pytest.mark.parametrize("text, where", [
    ('[plant]\nm1_kg = "heavy"\n', "plant.m1_kg"),
    ('[sim]\nsubsteps = "two"\n', "sim.substeps"),
    ("[controller]\ncross_term_scale = \"huge\"\n", "controller.cross_term_scale"),
    ("[plant]\nd_m = [1.0, 2.0]\n", "plant.d_m"),
    ("[plant]\nm1_kg = -1.0\n", "plant.m1_kg"),
    ("[plant]\nr1_m = nan\n", "finite"),
    ("[trigger]\neta = 0.0\n", "trigger.eta"),
])
def test_wrong_type_or_value_is_a_one_line_config_error(tmp_path: Path, text: str, where: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(_write(tmp_path, text))
    msg = str(info.value)
    assert where in msg and "\n" not in msg
    assert isinstance(info.value, SeaHilError)


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "absent.toml")


def test_invalid_toml_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(_write(tmp_path, "[plant\nm1_kg = 1\n"))
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path)  # a directory


def test_overlay_merges_nested_tables(tmp_path: Path) -> None:
    path = _write(tmp_path, "[controller]\nkp1 = 5.0\n[link.uplink]\ndelay_s = 0.02\n[disturbance]\nkind = \"sine\"\n")
    cfg = load_config(path)
    default = load_config()
    assert cfg.controller.kp1 == 5.0
    assert cfg.controller.c == default.controller.c and cfg.controller.kp2 == default.controller.kp2
    assert cfg.link.uplink.delay_s == 0.02 and cfg.link.uplink.loss == default.link.uplink.loss
    assert cfg.link.downlink == default.link.downlink
    assert cfg.disturbance.kind == "sine" and cfg.disturbance.frequency_hz == default.disturbance.frequency_hz
    assert cfg.plant == default.plant
    # programmatic overrides apply after the file
    cfg2 = load_config(path, {"controller": {"kp1": 7.0}, "link": {"uplink": {"loss": 0.1}}})
    assert cfg2.controller.kp1 == 7.0 and cfg2.link.uplink.delay_s == 0.02 and cfg2.link.uplink.loss == 0.1


def test_shipped_config_overlays_load() -> None:
    paper = load_config(REPO / "configs" / "paper.toml")
    assert (paper.controller.kp1, paper.controller.kp2, paper.trigger.eta) == (3.0, 5.0, 0.3)
    assert paper.controller.cross_term_scale == "paper"
    assert load_config(REPO / "configs" / "paper-trigger.toml").trigger.eta == 0.3


def test_config_to_toml_round_trips() -> None:
    cfg = load_config(overrides={"controller": {"kp1": 12.5}, "zenoh": {"connect": ["tcp/127.0.0.1:7447"]},
                                 "trajectory": {"csv_path": 'a "quoted" \\path'}})
    again = config_from_dict(tomllib.loads(config_to_toml(cfg)))
    assert isinstance(again, SeaHilConfig) and again == cfg
