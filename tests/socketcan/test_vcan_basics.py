"""Real SocketCAN on vcan0: python-can <-> python-can, cansend -> python-can, python-can -> candump.

Only runs where vcan0 exists (see conftest.py); elsewhere: ``scripts/with-vcan -- python -m pytest tests/socketcan``.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import can
import pytest
from socketcan_helpers import parse_candump_line

RECV_TIMEOUT_S = 5.0
DEADLINE_S = 10.0


def only(can_id: int, extended: bool = False) -> list[dict[str, object]]:
    """python-can filter accepting exactly ``can_id`` (other traffic on a shared vcan0 is ignored)."""
    mask = 0x1FFFFFFF if extended else 0x7FF
    return [{"can_id": can_id, "can_mask": mask, "extended": extended}]


def test_two_buses_exchange_frames(open_can_bus: Callable[..., can.BusABC]) -> None:
    sender = open_can_bus(can_filters=only(0x7FE))
    receiver = open_can_bus(can_filters=only(0x1ABCDE01, extended=True) + only(0x111))
    sent = [can.Message(arbitration_id=0x111, data=b"\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDE01, data=bytes(range(8)), is_extended_id=True),
            can.Message(arbitration_id=0x111, data=b"", is_extended_id=False)]
    for message in sent:
        sender.send(message, timeout=RECV_TIMEOUT_S)
    received = [receiver.recv(timeout=RECV_TIMEOUT_S) for _ in sent]
    assert all(m is not None for m in received), received
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in received] == \
        [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in sent]


def test_sender_does_not_receive_own_frames_by_default(open_can_bus: Callable[..., can.BusABC]) -> None:
    sender = open_can_bus(can_filters=only(0x222))
    receiver = open_can_bus(can_filters=only(0x222))
    sender.send(can.Message(arbitration_id=0x222, data=b"\xAA", is_extended_id=False))
    assert receiver.recv(timeout=RECV_TIMEOUT_S) is not None  # delivered: the loopback path works
    assert sender.recv(timeout=0.05) is None


def test_burst_arrives_complete_and_in_order(open_can_bus: Callable[..., can.BusABC]) -> None:
    sender = open_can_bus()
    receiver = open_can_bus(can_filters=only(0x333))
    count = 200
    for index in range(count):
        sender.send(can.Message(arbitration_id=0x333, data=index.to_bytes(2, "big"), is_extended_id=False),
                    timeout=RECV_TIMEOUT_S)
    received = []
    for _ in range(count):
        message = receiver.recv(timeout=RECV_TIMEOUT_S)
        assert message is not None, f"lost frames: got {len(received)} of {count}"
        received.append(int.from_bytes(message.data, "big"))
    assert received == list(range(count))


def test_cansend_reaches_python_can(open_can_bus: Callable[..., can.BusABC],
                                    cansend: Callable[[str], None]) -> None:
    receiver = open_can_bus(can_filters=only(0x123))  # bound before the frame is sent: no race
    cansend("123#DEADBEEF")
    message = receiver.recv(timeout=RECV_TIMEOUT_S)
    assert message is not None
    assert (message.arbitration_id, message.is_extended_id, bytes(message.data)) == \
        (0x123, False, b"\xDE\xAD\xBE\xEF")


def test_python_can_frame_seen_by_candump(open_can_bus: Callable[..., can.BusABC], start_candump,
                                          vcan_channel: str) -> None:
    dump = start_candump("-n", "1", filters="456:7FF")
    sender = open_can_bus()
    message = can.Message(arbitration_id=0x456, data=b"\x10\x20\x30", is_extended_id=False)
    deadline_ns = time.monotonic_ns() + int(DEADLINE_S * 1e9)
    frame = None
    while frame is None and time.monotonic_ns() < deadline_ns:
        sender.send(message)  # candump may not have bound its socket yet: resend until it prints
        frame = dump.next_frame(timeout_s=0.2)
    assert frame is not None, "candump printed nothing before the deadline"
    assert (frame.channel, frame.arbitration_id, frame.is_extended_id, frame.data) == \
        (vcan_channel, 0x456, False, b"\x10\x20\x30")
    assert dump.wait() == 0  # -n 1: candump exits by itself after one frame


@pytest.mark.parametrize("line,expected", [
    ("(1.000001) vcan0 123#DEADBEEF", ("vcan0", 0x123, False, b"\xDE\xAD\xBE\xEF")),
    ("(2.5) vcan0 1ABCDE01#", ("vcan0", 0x1ABCDE01, True, b"")),
])
def test_parse_candump_line(line: str, expected: tuple[object, ...]) -> None:
    assert tuple(parse_candump_line(line)) == expected
