"""`--period-ms` (simulate, run, sweep): the outer sample period on the wire, parsed and validated in one place
(sea_hil/commands/common.py); the inner loop keeps its rate."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from sea_hil.cli import main
from sea_hil.commands.common import check_period_ms
from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError


def test_period_is_converted_and_validated_against_the_inner_period():
    cfg = load_config(None)
    assert check_period_ms(30, cfg) == pytest.approx(0.030)
    assert check_period_ms(1, cfg) == pytest.approx(0.001)
    for bad, msg in ((0, "positive"), (-10, "positive"), (float("nan"), "positive"), (float("inf"), "positive"),
                     (2.5, "whole multiple of the inner-loop period 1 ms")):
        with pytest.raises(ConfigError, match=msg):
            check_period_ms(bad, cfg)
    coarse = load_config(None, {"can": {"feedback_rate_hz": 500.0}})   # inner period 2 ms
    with pytest.raises(ConfigError, match="2 ms"):
        check_period_ms(5, coarse)


@pytest.mark.parametrize("command", ["simulate", "run", "sweep"])
@pytest.mark.parametrize("value,msg", [("0", "must be a positive"), ("1.5", "whole multiple"), ("x", "")])
def test_bad_period_is_a_one_line_error_before_anything_runs(tmp_path, capsys, command, value, msg):
    try:
        rc = main([command, "--period-ms", value, "--out", str(tmp_path / "o")])
    except SystemExit as stop:      # argparse's own type error
        rc = stop.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "--period-ms" in err and msg in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_simulate_tt_at_a_reduced_rate_sends_one_state_and_one_setpoint_per_period(tmp_path: Path):
    short = tmp_path / "short.toml"
    short.write_text("[trajectory]\nperiod_s = 1.0\n", encoding="utf-8")
    out = tmp_path / "o"
    assert main(["simulate", "--controller", "tt", "--period-ms", "20", "--config", str(short), "--json",
                 "--out", str(out)]) == 0
    tx = json.loads((out / "summary.json").read_text(encoding="utf-8"))["transmissions"]
    assert tx["uplink_msgs"] == tx["downlink_msgs"] == 50          # 1 s at 20 ms (10 ms: 100)
    assert tx["total_msgs"] == 100 and tx["total_bytes"] == tx["uplink_bytes"] + tx["downlink_bytes"]
