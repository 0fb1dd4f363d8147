"""`sea-hil run` with its drivers in processes of their own (`[timing] driver_process`, issue 33;
sea_hil/session/driver_process.py): the bus mapping and the child's command line (pure), a short real-time session
per CAN profile whose driver child's final counters reach the recording and summary and whose recording holds every
frame the driver sent, and a driver child that dies mid-session failing the session with every child ended."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import psutil
import pytest
from mcap.reader import make_reader

from sea_hil.commands.plant import bus_routes
from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError, SeaHilError
from sea_hil.session.driver_process import DriverProcess, plant_command, process_bus, process_limbs
from sea_hil.session.limbs import Limb
from sea_hil.session.run import RunOptions, run_session, split_drivers

# a 1 s gait after a 0.25 s lead-in (the drive limits and the setpoint envelope are derived for the 10 s gait: off)
SHORT: dict[str, Any] = {"trajectory": {"period_s": 1.0, "lead_in_s": 0.25},
                         "safety": {"drive": {"enabled": False}, "setpoint": {"enabled": False}},
                         "verdict": {"floor_measure_s": 0.1}}


def test_only_one_process_buses_are_replaced() -> None:
    assert process_bus("virtual:sea-hil0", "run-ab12") == "ipc:run-ab12-sea-hil0"
    for spec in ("socketcan:vcan0", "ipc:mine", "udp_multicast:239.74.163.2"):
        assert process_bus(spec, "run-ab12") == spec
    cfg = load_config(overrides={"can": {"emulate_bitrate": True}})
    with pytest.raises(ConfigError, match="emulate_bitrate"):
        process_limbs(cfg, (Limb("limb", 1, "virtual:x"),), "run-ab12")


def test_driver_command_names_each_bus_once_or_once_per_node(tmp_path: Path) -> None:
    one = plant_command(tmp_path / "p.toml", ((1, "ipc:a"), (2, "ipc:a")))
    assert one[one.index("plant"):] == ["plant", "--config", str(tmp_path / "p.toml"), "--hold", "--json",
                                        "--can", "ipc:a", "--node", "1", "--node", "2"]
    two = plant_command(tmp_path / "p.toml", ((1, "ipc:a"), (2, "ipc:b"), (3, "ipc:b")))
    assert two[two.index("--can"):] == ["--can", "ipc:a", "--can", "ipc:b", "--can", "ipc:b",
                                        "--node", "1", "--node", "2", "--node", "3"]
    assert bus_routes(["ipc:a", "ipc:b", "ipc:b"], (1, 2, 3)) == {1: "ipc:a", 2: "ipc:b", 3: "ipc:b"}
    assert bus_routes(["ipc:a"], (1, 2)) is None
    with pytest.raises(ConfigError, match="one --can per --node"):
        bus_routes(["ipc:a", "ipc:b"], (1, 2, 3))


def test_lockstep_never_splits() -> None:
    cfg = load_config(overrides={"timing": {"driver_process": True}})
    assert split_drivers(cfg, RunOptions(lockstep=False))
    assert not split_drivers(cfg, RunOptions(lockstep=True))
    assert not split_drivers(cfg, RunOptions(lockstep=False, driver_process=False))
    assert split_drivers(load_config(), RunOptions(driver_process=True))
    assert not split_drivers(load_config(), RunOptions())


def test_unset_the_cia402_profile_splits_and_the_sea_profile_does_not() -> None:
    cia = load_config(overrides={"can": {"profile": "cia402"}})
    assert cia.timing.driver_process is None
    assert split_drivers(cia, RunOptions()) and not split_drivers(cia, RunOptions(lockstep=True))
    assert not split_drivers(cia, RunOptions(driver_process=False))
    assert not split_drivers(load_config(overrides={"can": {"profile": "cia402", "emulate_bitrate": True}}),
                             RunOptions())   # the bus-timing model is one process's: in-process unless asked
    assert not split_drivers(load_config(), RunOptions())


def _metadata(path: Path) -> dict[str, dict[str, str]]:
    with open(path, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


@pytest.mark.slow
@pytest.mark.parametrize("profile", ["sea", "cia402"])
def test_real_time_session_with_a_driver_process(tmp_path: Path, profile: str) -> None:
    seen: list[Any] = []
    cfg = load_config(overrides={**SHORT, "can": {"profile": profile}})
    s = run_session(cfg, RunOptions(controller="et", out=tmp_path / "run", progress=False, figures=False,
                                    driver_process=True, on_nodes=lambda plant, *_: seen.append(plant)))
    driver = seen[0]
    assert isinstance(driver, DriverProcess) and _gone(driver.pid)
    assert driver.routes[0][1].startswith("ipc:run-")   # the embedded bus became one that crosses processes
    meta = _metadata(tmp_path / "run" / "session.mcap")
    final, own = meta["sea-hil.final"], meta["sea-hil.driver"]
    assert meta["sea-hil.session"]["driver_process"] == "True"
    ticks = int(own["ticks"])
    assert ticks > 1000 and int(final["plant_ticks"]) == ticks == s["timing"]["driver"]["ticks"]
    assert int(final["plant_overruns"]) == int(own["overruns"]) == s["timing"]["driver"]["tick_misses"]
    assert s["completeness"]["complete"], s["completeness"]
    assert int(final["can_frames_missed"]) == 0 and int(final["dropped"]) == 0
    if profile == "sea":   # every executed tick's 3 feedback frames (and the initial sample's) recorded
        assert int(final["messages./can/feedback"]) == 3 * (ticks + 1)
        edge = meta["sea-hil.edge"]
        assert int(final["messages./can/command"]) == int(edge["commands_sent"]) + int(edge["arrival_commands"])
    else:   # the edge in this process is the bus's SYNC producer
        assert s["timing"]["sync"]["syncs"] > 1000
    assert s["verdict"]["status"] in ("ok", "degraded"), s["verdict"]


def _ours(p: psutil.Process) -> bool:
    """A process the session started (`python -m sea_hil...`: controllers, the recorder, the driver), not one of
    another fixture's (the UML guest of the SocketCAN suite runs beside these tests in CI)."""
    try:
        return any(part.startswith("sea_hil") for part in p.cmdline())
    except psutil.Error:
        return False


@pytest.mark.slow
def test_a_driver_process_that_dies_fails_the_session_and_nothing_is_left(tmp_path: Path) -> None:
    seen: list[Any] = []

    def kill_driver(plant: Any, *_: Any) -> None:
        seen.append(plant)
        plant.proc.kill()

    with pytest.raises(SeaHilError, match="driver process .* exited"):
        run_session(load_config(overrides=SHORT), RunOptions(controller="et", out=tmp_path / "run", progress=False,
                                                             figures=False, driver_process=True,
                                                             on_nodes=kill_driver))
    assert _gone(seen[0].pid)
    assert not [p for p in psutil.Process().children(recursive=True) if _ours(p) and not _gone(p.pid)]
    final = _metadata(tmp_path / "run" / "session.mcap")["sea-hil.final"]
    assert "plant_ticks" not in final   # no count made up for a driver that gave none
