"""pytest plugin of sea-hil (entry point `pytest11`: active wherever sea-hil is installed). docs/api.md has an example.

Fixtures:
- `sea_config`: the configuration the other fixtures use (the embedded default; override the fixture in your
  conftest.py to use your own, e.g. `return sea_hil.load_config("my.toml")`).
- `sea_can_channel`: a CAN bus spec of its own for the test: a fresh `virtual:` channel, or `socketcan:vcan0` when the
  test is marked `@pytest.mark.sea_vcan` (skipped where there is no vcan0).
- `sea_driver`: an `EmulatedDriver` (node id 1, real time) started on `sea_can_channel`, closed after the test.
- `sea_bus`: a python-can bus on the same channel, for the test's own controller; shut down after the test.
- `sea_session`: a factory, `sea_session(controller="et", cycles=1, lockstep=True, ...)` -> a started `Session`
  (its own free loopback port and Zenoh sessions, outputs in the test's tmp_path); every session it made is
  closed after the test, also when the test fails. Strict by default: `wait()` raises `VerdictError` when the
  session's verdict is not ok (docs/verdict.md); `sea_session(strict=False)` returns the summary whatever it says.

Marker: `sea_vcan` — needs SocketCAN vcan0 (`ip link add dev vcan0 type vcan`); skipped when it is absent.
"""
from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterator
from typing import Any

import pytest

VCAN = "vcan0"


def vcan_available(name: str = VCAN) -> bool:
    return os.path.exists(f"/sys/class/net/{name}")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "sea_vcan: needs a SocketCAN vcan0 interface (skipped when there is none)")


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("sea_vcan") is not None and not vcan_available():
        pytest.skip(f"no SocketCAN interface {VCAN} (sea_vcan)")


@pytest.fixture
def sea_config() -> Any:
    from sea_hil.config.loader import load_config
    return load_config()


@pytest.fixture
def sea_can_channel(request: pytest.FixtureRequest) -> str:
    if request.node.get_closest_marker("sea_vcan") is not None:
        return f"socketcan:{VCAN}"
    return f"virtual:sea-hil-test-{uuid.uuid4().hex[:12]}"


@pytest.fixture
def sea_driver(sea_can_channel: str, sea_config: Any) -> Iterator[Any]:
    from sea_hil.api import EmulatedDriver
    with EmulatedDriver(sea_can_channel, 1, config=sea_config) as driver:
        yield driver


@pytest.fixture
def sea_bus(sea_can_channel: str) -> Iterator[Any]:
    from sea_hil.protocol.canbus import open_bus
    bus = open_bus(sea_can_channel)
    try:
        yield bus
    finally:
        bus.shutdown()


@pytest.fixture
def sea_session(sea_config: Any, tmp_path: Any) -> Iterator[Callable[..., Any]]:
    from sea_hil.api import Session
    made: list[Any] = []

    def make(controller: str = "et", cycles: int = 1, lockstep: bool = True, **kw: Any) -> Any:
        kw.setdefault("config", sea_config)
        kw.setdefault("strict", True)   # a session whose verdict is not ok fails the test (VerdictError)
        kw.setdefault("out", tmp_path / f"session{len(made)}")
        session = Session(controller=controller, cycles=cycles, lockstep=lockstep, **kw)
        made.append(session)
        return session.start()

    try:
        yield make
    finally:
        for session in made:
            session.close()
