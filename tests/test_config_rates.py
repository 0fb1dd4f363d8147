"""One source per rate: `controller.sample_period_s` (outer loop: state published and sampled) and
`can.feedback_rate_hz` (inner loop = drive feedback), read by the offline loop and the session nodes alike; the old
duplicates `controller.inner_rate_hz` / `zenoh.state_period_s` still load (moved, with a warning) unless they
contradict, and the dead keys `can.send_backoff_s` / `record.stats_period_s` are ignored with a warning."""
from __future__ import annotations

from pathlib import Path

import pytest

from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError
from sea_hil.offline.closed_loop import inner_ratio, simulate


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "old.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_old_rate_keys_move_to_their_one_source(tmp_path: Path) -> None:
    path = _write(tmp_path, "[controller]\ninner_rate_hz = 500.0\n[zenoh]\nstate_period_s = 0.02\n")
    with pytest.warns(FutureWarning) as record:
        cfg = load_config(path)
    messages = [str(w.message) for w in record]
    assert any("controller.inner_rate_hz is deprecated, use can.feedback_rate_hz" in m and str(path) in m
               for m in messages)
    assert any("zenoh.state_period_s is deprecated, use controller.sample_period_s" in m for m in messages)
    assert (cfg.can.feedback_rate_hz, cfg.controller.sample_period_s, inner_ratio(cfg)) == (500.0, 0.02, 10)


def test_old_key_contradicting_the_new_one_is_a_config_error(tmp_path: Path) -> None:
    path = _write(tmp_path, "[controller]\ninner_rate_hz = 500.0\n[can]\nfeedback_rate_hz = 1000.0\n")
    with pytest.raises(ConfigError, match="inner_rate_hz = 500.0 contradicts can.feedback_rate_hz = 1000.0"):
        load_config(path)
    with pytest.raises(ConfigError, match="state_period_s = 0.05 contradicts controller.sample_period_s = 0.01"):
        load_config(overrides={"zenoh": {"state_period_s": 0.05}, "controller": {"sample_period_s": 0.01}})


def test_old_key_equal_to_the_new_one_only_warns(tmp_path: Path) -> None:
    path = _write(tmp_path, "[controller]\ninner_rate_hz = 1000.0\n[can]\nfeedback_rate_hz = 1000.0\n")
    with pytest.warns(FutureWarning, match="inner_rate_hz is deprecated"):
        assert load_config(path) == load_config()


def test_dead_keys_are_ignored_with_a_warning(tmp_path: Path) -> None:
    path = _write(tmp_path, "[can]\nsend_backoff_s = 0.001\n[record]\nstats_period_s = 2.0\n")
    with pytest.warns(FutureWarning) as record:
        cfg = load_config(path)
    assert cfg == load_config()
    assert sorted(str(w.message).split(": ")[1].split(" ")[0] for w in record) == [
        "can.send_backoff_s", "record.stats_period_s"]
    assert not hasattr(cfg.can, "send_backoff_s") and not hasattr(cfg.record, "stats_period_s")


@pytest.mark.parametrize("over", [{"controller": {"sample_period_s": 0.0105}},
                                  {"can": {"feedback_rate_hz": 50.0}}])   # 0.5 inner steps per sample
def test_sample_period_must_be_whole_inner_periods(over: dict) -> None:
    with pytest.raises(ConfigError, match="whole number"):
        load_config(overrides=over)


def test_offline_loop_runs_at_the_session_rates() -> None:
    cfg = load_config(overrides={"trajectory": {"period_s": 0.2}, "controller": {"sample_period_s": 0.02},
                                 "can": {"feedback_rate_hz": 500.0}})
    res = simulate(cfg, "tt")
    assert res.t_s[1] - res.t_s[0] == pytest.approx(0.02) and len(res.t_s) == 10
    assert res.inner_steps == 100          # one inner step per drive feedback sample (500 Hz over 0.2 s)
