"""`sea-hil simulate` end to end: summary.json, figures, compare.md, the acceptance criteria, and CLI errors."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from sea_hil.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _run(out: Path, *args: str) -> dict[str, Any]:
    assert main(["simulate", *args, "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, dict[str, Any]]]:
    out = {}
    for mode in ("tt", "et"):
        d = tmp_path_factory.mktemp(mode)
        out[mode] = (d, _run(d, "--controller", mode))
    return out


@pytest.mark.parametrize("mode", ["tt", "et"])
def test_summary_has_the_required_keys_and_figures(runs: dict, mode: str) -> None:
    out, s = runs[mode]
    assert s["controller"] == mode
    assert s["duration_s"] == pytest.approx(10.0)
    tx = s["transmissions"]     # the session's schema: setpoints down, one state per 10 ms sample up
    assert tx["downlink_msgs"] == sum(s["events_by_reason"].values()) > 0
    assert (tx["uplink_msgs"], tx["uplink_bytes"], tx["downlink_bytes"]) == (1000, 96 * 1000, 61 * tx["downlink_msgs"])
    assert set(s["timing"]) == {"cpu_s"}
    for key in ("max_abs_error_rad", "rms_error_rad"):
        vals = s["tracking"][key]
        assert len(vals) == 2 and all(math.isfinite(v) and v >= 0 for v in vals)
    assert all(s["tracking"]["rms_error_rad"][j] <= s["tracking"]["max_abs_error_rad"][j] for j in range(2))
    ie = s["inter_event_s"]
    assert 0 < ie["min"] <= ie["median"] <= ie["max"]
    assert len(s["max_abs_voltage_v"]) == 2 and all(0 < v <= 24.0 for v in s["max_abs_voltage_v"])
    for name in (f"tracking_{mode}.png", f"inter_event_{mode}.png"):
        data = (out / name).read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 5000


def test_tt_transmits_every_sample(runs: dict) -> None:
    s = runs["tt"][1]
    assert s["transmissions"]["downlink_msgs"] == 1000  # 10 s at 10 ms
    assert s["inter_event_s"]["min"] == pytest.approx(0.01) and s["inter_event_s"]["max"] == pytest.approx(0.01)
    assert s["events_by_reason"] == {"TIME": 1000}


def test_acceptance_criteria(runs: dict) -> None:
    tt, et = runs["tt"][1], runs["et"][1]
    tt_max, et_max = max(tt["tracking"]["max_abs_error_rad"]), max(et["tracking"]["max_abs_error_rad"])
    assert tt_max < 0.1 and et_max < 0.1
    assert et["transmissions"]["downlink_msgs"] <= tt["transmissions"]["downlink_msgs"] / 3
    assert et_max <= 1.2 * tt_max
    # ET events are spaced by whole samples and bounded by the heartbeat
    assert et["inter_event_s"]["min"] >= 0.01 - 1e-9 and et["inter_event_s"]["max"] <= 0.25 + 1e-9
    assert et["events_by_reason"]["INITIAL"] == 1


def test_compare_writes_markdown(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--compare", "--out", str(tmp_path)]) == 0
    table = (tmp_path / "compare.md").read_text(encoding="utf-8")
    assert table.startswith("# TT-SMC vs ET-SMC")
    assert "| transmissions per run | 1000 |" in table and "max abs tracking error" in table
    tt = json.loads((tmp_path / "tt" / "summary.json").read_text())
    et = json.loads((tmp_path / "et" / "summary.json").read_text())
    ratio = et["transmissions"]["downlink_msgs"] / tt["transmissions"]["downlink_msgs"]
    assert f"| {ratio:.3f} |" in table
    assert (tmp_path / "et" / "tracking_et.png").exists() and (tmp_path / "tt" / "inter_event_tt.png").exists()
    assert "| transmissions per run |" in capsys.readouterr().out


def test_simulate_with_a_csv_trajectory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "traj.csv"
    swing = [0.2 * math.sin(math.pi * k * 0.1) for k in range(21)]
    rows = [f"{k * 0.1:.1f},{0.05 + a:.9f},{0.55 + a:.9f}" for k, a in enumerate(swing)]
    csv.write_text("t,theta1,theta2\n" + "\n".join(rows) + "\n", encoding="utf-8")
    s = _run(tmp_path / "out", "--controller", "et", "--trajectory", str(csv), "--json")
    assert s["duration_s"] == pytest.approx(2.0)
    assert max(s["tracking"]["max_abs_error_rad"]) < 0.1
    assert json.loads(capsys.readouterr().out) == s  # --json: stdout is the same summary


def test_bad_trajectory_exits_2_with_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("t,theta1\n0,0\n1,0\n2,0\n3,0\n", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "simulate", "--trajectory", str(bad),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].startswith("sea-hil simulate: error:") and "theta2" in lines[0]
    assert not (tmp_path / "o" / "summary.json").exists()


def test_bad_config_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--config", str(tmp_path / "none.toml"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "config file not found" in err and err.count("\n") == 1


def test_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    assert "simulate" in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:
        main(["simulate", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "--controller" in out and "--compare" in out and "--trajectory" in out
