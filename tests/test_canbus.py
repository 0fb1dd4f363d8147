"""Tests of protocol/canbus.py: spec parsing, opening buses, bounded send retry."""
from __future__ import annotations

import errno
import os
import types
import uuid
from collections.abc import Iterator

import can
import pytest
from can.interfaces.socketcan.socketcan import SocketcanBus

from sea_hil.config.wire_names import parse_can_spec
from sea_hil.errors import BusError, ConfigError
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import VoltageCmd
from sea_hil.protocol.canbus import is_buffer_full, open_bus, send_with_retry
from sea_hil.stats.can_bits import can_frame_bits


@pytest.mark.parametrize("spec,expected", [
    ("socketcan:vcan0", ("socketcan", "vcan0")),
    ("socketcan:can-1.x_2", ("socketcan", "can-1.x_2")),
    ("virtual:sea-hil", ("virtual", "sea-hil")),
    ("virtual:a:b", ("virtual", "a:b")),
    ("udp_multicast:239.74.163.2", ("udp_multicast", "239.74.163.2")),
    ("udp_multicast:ff15::7079", ("udp_multicast", "ff15::7079")),
])
def test_parse_can_spec(spec: str, expected: tuple[str, str]) -> None:
    assert parse_can_spec(spec) == expected


@pytest.mark.parametrize("spec,match", [
    ("", "expected 'socketcan"), ("vcan0", "expected 'socketcan"), (None, "expected"),
    ("pcan:PCAN_USBBUS1", "unknown interface 'pcan'"), ("SocketCAN:vcan0", "unknown interface"),
    ("socketcan:", "not a network interface"), ("socketcan:a b", "not a network interface"),
    ("socketcan:sixteen_chars_xx", "not a network interface"), ("virtual:", "non-empty"),
    ("virtual: x", "non-empty"), ("udp_multicast:10.0.0.1", "multicast group"),
    ("udp_multicast:not-an-ip", "multicast group"), ("udp_multicast:", "multicast group"),
])
def test_parse_can_spec_errors(spec, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_can_spec(spec)


@pytest.fixture
def virtual_pair() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    spec = f"virtual:test-{uuid.uuid4().hex}"
    a = open_bus(spec, receive_own_messages=True)
    try:
        b = open_bus(spec)
        try:
            yield a, b
        finally:
            b.shutdown()
    finally:
        a.shutdown()


def test_two_virtual_buses_exchange_a_frame(virtual_pair) -> None:
    a, b = virtual_pair
    codec = SeaCodec()
    cmd = VoltageCmd(3, (1.25, -0.5), 42)
    assert send_with_retry(a, codec.encode(cmd), retries=2, backoff_s=0.0) == 0
    got = b.recv(timeout=5.0)
    assert got is not None and codec.decode(got) == cmd
    own = a.recv(timeout=5.0)  # receive_own_messages=True reflects the frame back to the sender
    assert own is not None and codec.decode(own) == cmd
    assert b.recv(timeout=0.0) is None


def test_open_bus_failure_is_bus_error() -> None:
    with pytest.raises(BusError, match="cannot open CAN bus 'socketcan:seahilnope0'"):
        open_bus("socketcan:seahilnope0")
    with pytest.raises(BusError, match="cannot receive its own"):
        open_bus("udp_multicast:239.74.163.2", receive_own_messages=True)
    with pytest.raises(ConfigError):
        open_bus("bogus")


class FakeBus:
    """A bus whose send fails with `errors` (in order) before succeeding."""

    def __init__(self, errors: list[BaseException]) -> None:
        self.errors = list(errors)
        self.sends = 0

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sends += 1
        if self.errors:
            raise self.errors.pop(0)


def _python_can_enobufs() -> can.CanOperationError:
    """The exact error python-can's SocketcanBus raises when the kernel answers ENOBUFS."""
    def send(_data: bytes) -> int:
        raise OSError(errno.ENOBUFS, os.strerror(errno.ENOBUFS))
    fake_self = types.SimpleNamespace(channel="vcan0", socket=types.SimpleNamespace(send=send))
    try:
        SocketcanBus._send_once(fake_self, b"\0" * 16)  # type: ignore[arg-type]
    except can.CanOperationError as err:
        return err
    raise AssertionError("python-can did not raise")


def test_python_can_exposes_enobufs_as_error_code() -> None:
    err = _python_can_enobufs()
    assert err.error_code == errno.ENOBUFS and is_buffer_full(err)
    assert is_buffer_full(can.CanOperationError("Transmit buffer full"))
    assert is_buffer_full(OSError(errno.ENOBUFS, "No buffer space available"))
    assert not is_buffer_full(can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN))


@pytest.mark.parametrize("failures", [0, 1, 3])
def test_send_with_retry_retries_enobufs(failures: int) -> None:
    bus, slept = FakeBus([_python_can_enobufs() for _ in range(failures)]), []
    msg = can.Message(arbitration_id=0x21, data=bytes(5), is_extended_id=False)
    used = send_with_retry(bus, msg, retries=3, backoff_s=0.001, sleep=slept.append)  # type: ignore[arg-type]
    assert used == failures
    assert bus.sends == failures + 1 and slept == [0.001] * failures


def test_send_with_retry_gives_up_after_last_retry() -> None:
    errors = [can.CanOperationError("Transmit buffer full")] * 2 + [_python_can_enobufs()] * 3
    bus, slept = FakeBus(errors), []
    msg = can.Message(arbitration_id=0x21, data=bytes(5), is_extended_id=False)
    with pytest.raises(BusError, match="still full after 4 retries"):
        send_with_retry(bus, msg, retries=4, backoff_s=0.002, sleep=slept.append)  # type: ignore[arg-type]
    assert bus.sends == 5 and slept == [0.002] * 4


def test_send_with_retry_does_not_retry_other_errors() -> None:
    bus, slept = FakeBus([can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)]), []
    msg = can.Message(arbitration_id=0x21, data=bytes(5), is_extended_id=False)
    with pytest.raises(BusError, match="Network is down"):
        send_with_retry(bus, msg, retries=5, backoff_s=0.0, sleep=slept.append)  # type: ignore[arg-type]
    assert bus.sends == 1 and slept == []
    with pytest.raises(ConfigError):
        send_with_retry(bus, msg, retries=-1, backoff_s=0.0)  # type: ignore[arg-type]


@pytest.mark.socketcan
@pytest.mark.sea_vcan   # the sea-hil pytest plugin skips it where there is no vcan0 (use scripts/with-vcan)
def test_socketcan_vcan0_exchange() -> None:
    a, b = open_bus("socketcan:vcan0"), open_bus("socketcan:vcan0")
    try:
        codec = SeaCodec()
        send_with_retry(a, codec.encode(VoltageCmd(1, (2.0, -2.0), 9)), retries=3, backoff_s=0.001)
        got = b.recv(timeout=5.0)
        assert got is not None and codec.decode(got) == VoltageCmd(1, (2.0, -2.0), 9)
    finally:
        a.shutdown()
        b.shutdown()


def test_frame_bits_and_documented_bus_load() -> None:
    assert [can_frame_bits(n) for n in (0, 5, 7, 8)] == [55, 105, 125, 135]
    assert [can_frame_bits(n, worst_case=False) for n in (0, 5, 7, 8)] == [47, 87, 103, 111]
    dlc = {m.name: m.length for m in load_database().messages}
    feedback = sum(can_frame_bits(dlc[n]) for n in ("FEEDBACK_ANGLE", "FEEDBACK_JOINT1", "FEEDBACK_JOINT2"))
    assert feedback == 405  # docs/can-protocol.md: 40.5 % of 1 Mbit/s at 1 kHz
    per_s = 1000 * (feedback + can_frame_bits(dlc["VOLTAGE_CMD"])) + 10 * can_frame_bits(dlc["HEARTBEAT"])
    assert per_s == 511_350  # 51.1 % with the inner loop on the edge
