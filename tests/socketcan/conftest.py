"""Fixtures for tests that need a real SocketCAN interface (``vcan0``) and, optionally, netns + netem.

Every test in this directory is marked ``socketcan`` and skipped unless the interface exists and is up. On a
host without CAN support run them through User Mode Linux: ``scripts/with-vcan -- python -m pytest tests/socketcan``
(see docs/vcan-uml.md). Reusable fixtures:

- ``vcan_channel`` -> "vcan0" (env ``SEA_HIL_VCAN_CHANNEL`` overrides);
- ``open_can_bus(**kwargs)`` -> a python-can socketcan bus on that channel, shut down at teardown;
- ``cansend(frame)`` -> runs ``cansend <channel> <frame>`` (can-utils syntax, e.g. "123#DEADBEEF");
- ``start_candump(*args)`` -> a running ``candump -L`` (:class:`CanDump`), ended at teardown;
- ``netns(prefix)`` -> name of a fresh network namespace, deleted at teardown (root only);
- ``require_netem`` -> skips unless a netem qdisc can be added in a fresh namespace;
- ``veth_namespaces`` -> (server, client) namespaces joined by a veth pair (``netns_helpers.veth_pair``);
- ``gait_slice`` -> the lockstep node sessions' config and its ``sea-hil run --lockstep`` summary, made once.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import can
import pytest
from netns_helpers import run, veth_pair
from session_nodes import SLICE_S, GaitSlice, lockstep_run_summary, write_gait_slice_config
from socketcan_helpers import PROCESS_TIMEOUT_S, CanDump, interface_is_up

HERE = Path(__file__).resolve().parent


def channel_name() -> str:
    """The SocketCAN interface these tests use."""
    return os.environ.get("SEA_HIL_VCAN_CHANNEL", "vcan0")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark this directory's tests ``socketcan`` and skip them when the interface is missing."""
    del config
    skip = None if interface_is_up(channel_name()) else pytest.mark.skip(
        reason=f"no SocketCAN interface {channel_name()} (run through scripts/with-vcan)")
    for item in items:
        if HERE in item.path.parents:
            item.add_marker(pytest.mark.socketcan)
            if skip is not None:
                item.add_marker(skip)


def require_tool(name: str) -> str:
    """Path of command-line tool ``name``; skips the test if it is not installed."""
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not installed (apt-get install can-utils iproute2)")
    return path


@pytest.fixture(scope="session")
def vcan_channel() -> str:
    """Name of the SocketCAN interface under test ("vcan0")."""
    return channel_name()


@pytest.fixture
def open_can_bus(vcan_channel: str) -> Iterator[Callable[..., can.BusABC]]:
    """Factory of python-can socketcan buses on ``vcan_channel``; all are shut down at teardown."""
    buses: list[can.BusABC] = []

    def _open(**kwargs: object) -> can.BusABC:
        bus = can.Bus(interface="socketcan", channel=vcan_channel, **kwargs)
        buses.append(bus)
        return bus

    yield _open
    for bus in buses:
        bus.shutdown()


@pytest.fixture
def cansend(vcan_channel: str) -> Callable[[str], None]:
    """Function sending one frame with can-utils ``cansend`` (frame syntax "123#DEADBEEF")."""
    tool = require_tool("cansend")

    def _send(frame: str) -> None:
        subprocess.run([tool, vcan_channel, frame], check=True, stdin=subprocess.DEVNULL,
                       capture_output=True, timeout=PROCESS_TIMEOUT_S)

    return _send


@pytest.fixture
def start_candump(vcan_channel: str) -> Iterator[Callable[..., CanDump]]:
    """Factory ``(*args, filters="")`` starting ``candump -L [args] <channel>[,filters]``; ended at teardown."""
    require_tool("candump")
    dumps: list[CanDump] = []

    def _start(*args: str, filters: str = "") -> CanDump:
        dump = CanDump(vcan_channel, *args, filters=filters)
        dumps.append(dump)
        return dump

    yield _start
    for dump in dumps:
        dump.stop()


@pytest.fixture
def netns() -> Iterator[Callable[[str], str]]:
    """Factory creating uniquely named network namespaces (``ip netns add``); deleted at teardown."""
    require_tool("ip")
    names: list[str] = []

    def _add(prefix: str) -> str:
        name = f"{prefix}-{uuid.uuid4().hex[:8]}"
        run("ip", "netns", "add", name)
        names.append(name)
        return name

    yield _add
    for name in names:
        subprocess.run(["ip", "netns", "del", name], check=False, capture_output=True, timeout=PROCESS_TIMEOUT_S)


@pytest.fixture(scope="session")
def require_netem() -> None:
    """Skip unless this kernel lets us add a netem qdisc in a fresh network namespace."""
    for tool in ("unshare", "ip", "tc"):
        require_tool(tool)
    probe = "ip link add d0 type dummy && tc qdisc add dev d0 root netem delay 1ms"
    result = subprocess.run(["unshare", "--net", "sh", "-c", probe], check=False, stdin=subprocess.DEVNULL,
                            capture_output=True, text=True, timeout=PROCESS_TIMEOUT_S)
    if result.returncode != 0:
        pytest.skip(f"netem unavailable here: {result.stderr.strip() or result.returncode}")


@pytest.fixture
def veth_namespaces(require_netem: None, netns: Callable[[str], str]) -> tuple[str, str]:
    """(server namespace, client namespace) joined by veth ``v0``/``v1`` with addresses and links up."""
    del require_netem
    return veth_pair(netns)


@pytest.fixture(scope="session")
def gait_slice(tmp_path_factory: pytest.TempPathFactory) -> GaitSlice:
    """The config the lockstep node sessions share and the summary `sea-hil run --lockstep` writes for it: each
    session's summary must equal it in every deterministic field; one reference run serves them all."""
    directory = tmp_path_factory.mktemp("gait-slice")
    config = write_gait_slice_config(directory, SLICE_S)
    return GaitSlice(config, SLICE_S, lockstep_run_summary(config, directory / "run"))
