"""Issue 16's scheme is the default (trigger at the edge checked every outer sample, model lookahead, delay
prediction); the paper's stays selectable, and the commands that need every state up pick the paper's placement."""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from sea_hil.commands.common import config_from_args
from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError
from sea_hil.session.run import RunOptions, run_session

PAPER_PATH = Path(__file__).resolve().parent / "fixtures" / "pre_refactor" / "paper_path.toml"


def _scheme(cfg) -> tuple:
    return cfg.trigger.placement, cfg.trigger.edge_check, cfg.trigger.edge_model, cfg.controller.compensation


def _args(**kw) -> argparse.Namespace:
    return argparse.Namespace(**{"config": None, "trigger": None, "compensation": None, **kw})


def test_the_default_is_the_edge_trigger_with_model_lookahead_and_prediction():
    assert _scheme(load_config()) == ("edge", "outer", True, "predict")
    assert _scheme(config_from_args(_args(controller="et", inner="edge"))) == ("edge", "outer", True, "predict")


def test_the_papers_scheme_is_selectable_and_the_equality_overlay_selects_it():
    paper = config_from_args(_args(controller="et", inner="edge", trigger="controller", compensation="none"))
    assert (paper.trigger.placement, paper.controller.compensation) == ("controller", "none")
    fixed = load_config(PAPER_PATH)
    assert (fixed.trigger.placement, fixed.trigger.edge_model, fixed.controller.compensation) == \
        ("controller", False, "none")


def test_remote_inner_loop_and_external_controller_run_the_trigger_at_the_controller():
    remote = config_from_args(_args(controller="et", inner="remote"))
    assert (remote.trigger.placement, remote.controller.compensation) == ("controller", "none")
    external = config_from_args(_args(controller="external", inner="edge"))
    assert external.trigger.placement == "controller"
    assert config_from_args(_args(controller="external", inner="edge", trigger="edge")).trigger.placement == "edge"
    with pytest.raises(ConfigError, match="--inner remote"):
        config_from_args(_args(controller="et", inner="remote", trigger="edge"))


def test_a_remote_inner_session_with_the_edge_trigger_is_a_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="inner 'remote'"):
        run_session(load_config(), RunOptions(out=tmp_path / "run", inner="remote", progress=False))
