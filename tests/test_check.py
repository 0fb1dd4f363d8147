"""Inputs checked before anything moves (issue 29 part 3, sea_hil/input_check.py): `sea-hil check` passes every
shipped config and trajectory, and gives the one right line (exit 2) for a broken one of each key class; `run`
refuses the same config at load with that line (exit 2, nothing started) unless forced past it."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from sea_hil.cli import main
from sea_hil.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
SHIPPED_CONFIGS = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "tests" / "fixtures").rglob("*.toml"))
SHIPPED_TRAJECTORIES = sorted((ROOT / "configs").glob("*.csv"))
SHIPPED_TRACES = sorted((ROOT / "configs" / "traces").glob("*.csv"))


def _lines(err: str) -> list[str]:
    assert "Traceback" not in err
    return [ln for ln in err.splitlines() if ln.strip()]


def test_shipped_configs_and_trajectories_are_found() -> None:
    assert len(SHIPPED_CONFIGS) >= 7 and SHIPPED_TRAJECTORIES and SHIPPED_TRACES


@pytest.mark.parametrize("path", SHIPPED_CONFIGS + [None], ids=lambda p: "default" if p is None else p.name)
def test_every_shipped_config_passes(path: Path | None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check"] + ([] if path is None else ["--config", str(path)])) == 0
    out, err = capsys.readouterr()
    assert out.strip().endswith(": ok") and not _lines(err)


@pytest.mark.parametrize("csv", SHIPPED_TRAJECTORIES, ids=lambda p: p.name)
def test_every_shipped_trajectory_passes(csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--trajectory", str(csv)]) == 0
    assert capsys.readouterr().out.strip().endswith(": ok")


@pytest.mark.parametrize("trace", SHIPPED_TRACES, ids=lambda p: p.name)
def test_every_shipped_link_trace_passes(trace: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--uplink", f"trace={trace}", "--downlink", f"trace={trace}"]) == 0
    assert capsys.readouterr().out.strip().endswith(": ok")


def _csv(tmp: Path, rows: list[tuple[float, float, float]]) -> str:
    p = tmp / "traj.csv"
    p.write_text("t,theta1,theta2\n" + "".join(f"{t},{a},{b}\n" for t, a, b in rows), encoding="utf-8")
    return str(p)


def _smooth(t0: float = 0.0, hip: float = 0.05, amp: float = 0.1) -> list[tuple[float, float, float]]:
    import math
    return [(t0 + 0.05 * i, hip + amp * math.sin(2 * math.pi * i / 100), 0.2831) for i in range(101)]


# (toml, trajectory rows or None, the key the line must name, words it must contain)
BROKEN = {
    "start_above_soft_limit": ("[plant]\ninitial_theta_rad = [0.9, 1.3]\n", None, "plant.initial_theta_rad",
                               ("hip", "0.9", "safety.drive.position_max_rad[0] = 0.66")),
    "start_beyond_end_stop": ("[plant]\ninitial_theta_rad = [0.05, -0.7]\n[safety.drive]\nenabled = false\n", None,
                              "plant.initial_theta_rad", ("knee", "-0.7", "plant.end_stops.min_rad[1] = -0.5")),
    "gait_too_fast": ("[trajectory]\nperiod_s = 1.5\n[safety.setpoint]\nenabled = false\n", None,
                      "trajectory.period_s", ("knee trajectory velocity", "safety.drive.velocity_max_rad_s[1] = 2")),
    "envelope": ("[safety.setpoint]\ndeflection_max_m = [0.0001, 0.002]\n", None, "trajectory.period_s",
                 ("feed-forward deflection", "safety.setpoint.deflection_max_m")),
    "spring_force": ("[safety.drive]\nspring_force_max_n = [1.0, 60.0]\n", None, "trajectory.period_s",
                     ("hip feed-forward spring force", "safety.drive.spring_force_max_n[0] = 1")),
    "csv_not_from_zero": ("", _smooth(t0=1.0), "trajectory.csv_path", ("first sample is at t = 1 s",)),
    "csv_not_increasing": ("", [(0.0, 0.05, 0.28), (0.1, 0.05, 0.28), (0.1, 0.06, 0.28), (0.2, 0.05, 0.28),
                                (0.3, 0.05, 0.28)], "trajectory.csv_path", ("not strictly increasing",)),
    "csv_outside_limits": ("", _smooth(amp=0.8), "trajectory.csv_path",
                           ("hip trajectory angle", "safety.drive.position_max_rad[0] = 0.66")),
    "csv_path_empty": ('[trajectory]\nkind = "csv"\ncsv_path = ""\n', None, "trajectory.csv_path",
                       ("needs trajectory.csv_path",)),
    "missing_trace": ('[link.uplink]\ntrace_path = "/nonexistent/trace.csv"\n', None, "link.uplink.trace_path",
                      ("/nonexistent/trace.csv",)),
    "answer_deadline": ("[link.uplink]\ndelay_s = 0.15\n[link.downlink]\ndelay_s = 0.1\n", None,
                        "safety.setpoint.max_answer_age_s", ("0.25 s", "every setpoint would be late")),
    "inter_event_below_sample": ("[trigger]\nmax_inter_event_s = 0.005\n", None, "trigger.max_inter_event_s",
                                 ("below one sample",)),
    "watchdog_too_short": ("[can]\nwatchdog_timeout_s = 0.001\n", None, "can.watchdog_timeout_s",
                           ("two feedback periods",)),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_broken_input_is_one_line_naming_its_key(name: str, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    toml, rows, key, words = BROKEN[name]
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(toml, encoding="utf-8")
    argv = ["check", "--config", str(cfg)] + (["--trajectory", _csv(tmp_path, rows)] if rows else [])
    assert main(argv) == 2
    lines = _lines(capsys.readouterr().err)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"sea-hil check: error: {key}: "), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])


def test_run_refuses_the_start_pose_at_load(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's case: one line naming the key, the joint, the value and the limit; exit 2; nothing ran."""
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(BROKEN["start_above_soft_limit"][0], encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", "--lockstep", "--controller", "et", "--cycles", "1", "--no-figures", "--config", str(cfg),
                 "--out", str(out)]) == 2
    lines = _lines(capsys.readouterr().err)
    assert len(lines) == 1
    assert lines[0].startswith("sea-hil run: error: plant.initial_theta_rad: hip start angle 0.9 rad is above "
                               "safety.drive.position_max_rad[0] = 0.66 rad")
    assert "--allow-unsafe-start" in lines[0]
    assert not out.exists()   # refused before anything was written or started


def test_check_inputs_false_lets_the_config_load(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sea_hil.cli import build_parser
    from sea_hil.commands.common import config_from_args
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(BROKEN["start_above_soft_limit"][0] + "[verdict]\ncheck_inputs = false\n", encoding="utf-8")
    args = build_parser().parse_args(["run", "--config", str(cfg), "--out", str(tmp_path)])
    assert config_from_args(args, check="session").plant.initial_theta_rad == (0.9, 1.3)
    cfg.write_text(BROKEN["start_above_soft_limit"][0], encoding="utf-8")
    with pytest.raises(ConfigError, match="plant.initial_theta_rad"):
        config_from_args(args, check="session")
    forced = build_parser().parse_args(["run", "--config", str(cfg), "--out", str(tmp_path), "--allow-unsafe-start"])
    assert config_from_args(forced, check="session").verdict.check_inputs is False   # the children see it too


def test_simulate_checks_what_its_offline_loop_has(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No drive firmware offline: a gait too fast for the drive's velocity limit simulates; an end stop still
    refuses the start pose."""
    from sea_hil.cli import build_parser
    from sea_hil.commands.common import config_from_args
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[trajectory]\nperiod_s = 0.5\n", encoding="utf-8")
    args = build_parser().parse_args(["simulate", "--config", str(cfg), "--out", str(tmp_path)])
    assert config_from_args(args, check="offline").trajectory.period_s == 0.5
    cfg.write_text(BROKEN["start_beyond_end_stop"][0], encoding="utf-8")
    with pytest.raises(ConfigError, match="plant.end_stops.min_rad"):
        config_from_args(args, check="offline")


def test_the_trajectory_csv_is_read_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The check reads the CSV once (the loader's own checks, the start time and the motion from one
    `make_trajectory`), not once for its start time and again for the motion."""
    from sea_hil.config.loader import load_config
    from sea_hil.input_check import problems
    csv = Path(_csv(tmp_path, _smooth()))
    opened: list[Path] = []
    real_open = Path.open

    def counting_open(self: Path, *args: Any, **kwargs: Any) -> Any:
        if self == csv:
            opened.append(self)
        return real_open(self, *args, **kwargs)
    monkeypatch.setattr(Path, "open", counting_open)
    cfg = load_config(overrides={"trajectory": {"kind": "csv", "csv_path": str(csv)}})
    assert problems(cfg) == [] and len(opened) == 1, opened
