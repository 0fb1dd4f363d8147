"""The `ipc` CAN bus (protocol/ipc_bus.py, protocol/ipc_wire.py): every member gets every frame of the others, in
order per sender, with flow control instead of loss; late joiners, dead and stuck members, CAN FD and flags,
malformed packets. Each test has its own channel directory (tmp_path); the multi-process tests end every process."""
from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from sea_hil.config.loader import load_config
from sea_hil.config.wire_names import parse_can_spec
from sea_hil.errors import ConfigError, MalformedFrame
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.ipc_bus import IpcBus, channel_dir
from sea_hil.protocol.ipc_wire import HEADER, MAGIC, decode_frame, encode_frame
from sea_hil.runtime.processes import end_process
from sea_hil.session.limbs import bus_specs

MEMBER = Path(__file__).resolve().parent / "ipc" / "member.py"
CH = "bus"
MakeBus = Callable[..., IpcBus]


@pytest.fixture
def bus_dir(tmp_path: Path) -> Iterator[str]:
    d = tmp_path / "ipc"
    d.mkdir()
    yield str(d)


@pytest.fixture
def make_bus(bus_dir: str) -> Iterator[MakeBus]:
    made: list[IpcBus] = []

    def make(**kwargs: Any) -> IpcBus:
        bus = IpcBus(CH, directory=bus_dir, **kwargs)
        made.append(bus)
        return bus

    yield make
    for b in made:
        b.shutdown()


def frame(i: int, arbitration_id: int = 0x123) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, data=i.to_bytes(4, "little"), is_extended_id=False)


def member(bus_dir: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, str(MEMBER), bus_dir, CH, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)


def wait_joined(proc: subprocess.Popen[str]) -> None:
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "joined"


def test_every_other_member_gets_every_frame_in_order_and_not_its_own(make_bus: MakeBus) -> None:
    a, b, c = make_bus(), make_bus(), make_bus()
    for i in range(100):
        a.send(frame(i))
    b.send(frame(1000, 0x7FF))
    got = {rx: [(m.arbitration_id, int.from_bytes(m.data, "little")) for m in iter(lambda rx=rx: rx.recv(0), None)]
           for rx in (b, c)}
    assert got[b] == [(0x123, i) for i in range(100)]                    # not its own
    assert [f for f in got[c] if f[0] == 0x123] == got[b] and [f for f in got[c] if f[0] != 0x123] == [(0x7FF, 1000)]
    assert [int.from_bytes(a.recv(0).data, "little")] == [1000] and a.recv(0) is None   # not its own
    assert a.frames_sent == 100 and a.member_count == 2 and a.frames_dropped == 0


def test_receive_own_messages_loops_back(make_bus: MakeBus) -> None:
    a, b = make_bus(receive_own_messages=True), make_bus()
    a.send(frame(7))
    assert a.recv(1.0).data == frame(7).data and b.recv(1.0).data == frame(7).data


def test_fd_error_remote_and_extended_frames_round_trip(make_bus: MakeBus) -> None:
    a, b = make_bus(fd=True), make_bus(fd=True)
    sent = [
        can.Message(arbitration_id=0x1ABCDEF0, is_extended_id=True, is_fd=True, bitrate_switch=True,
                    error_state_indicator=True, data=bytes(range(64))),
        can.Message(arbitration_id=0x12, is_extended_id=False, is_fd=True, data=bytes(range(12))),
        can.Message(arbitration_id=0x321, is_extended_id=False, is_remote_frame=True, dlc=6),
        can.Message(arbitration_id=0x0, is_extended_id=False, is_error_frame=True, data=b"\x01\x02\x00\x00"),
        can.Message(arbitration_id=0x7FF, is_extended_id=False, data=b""),
    ]
    for m in sent:
        a.send(m)
    for m in sent:
        r = b.recv(1.0)
        assert r is not None and r.is_rx and r.channel == CH and r.timestamp > 0
        assert r.equals(m, timestamp_delta=None, check_channel=False, check_direction=False), (r, m)
    with pytest.raises(can.CanOperationError, match="out of range"):
        a.send(can.Message(arbitration_id=0x800, is_extended_id=False, check=False))


def test_a_late_member_gets_only_frames_sent_after_it_joined(make_bus: MakeBus, bus_dir: str) -> None:
    a, b = make_bus(), make_bus()
    old_ns = os.stat(channel_dir(CH, bus_dir)).st_mtime_ns - 10**10
    os.utime(channel_dir(CH, bus_dir), ns=(old_ns, old_ns))   # a's listing is then settled: seen again by mtime only
    a.send(frame(1))
    late = make_bus()
    a.send(frame(2))
    assert [m.data[0] for m in iter(lambda: b.recv(0), None)] == [1, 2]
    assert [m.data[0] for m in iter(lambda: late.recv(0), None)] == [2]


def test_fileno_is_readable_exactly_while_a_frame_is_pending(make_bus: MakeBus) -> None:
    a, b = make_bus(), make_bus()
    assert select.select([b], [], [], 0)[0] == []
    a.send(frame(1))
    a.send(frame(2))
    assert select.select([b], [], [], 5.0)[0] == [b]
    assert b.recv(0).data[0] == 1
    assert select.select([b], [], [], 0)[0] == [b]
    assert b.recv(0).data[0] == 2
    assert select.select([b], [], [], 0)[0] == [] and b.recv(0) is None


def test_filters_apply(make_bus: MakeBus) -> None:
    a, b = make_bus(), make_bus(can_filters=[{"can_id": 0x200, "can_mask": 0x7FF}])
    a.send(frame(1, 0x100))
    a.send(frame(2, 0x200))
    assert b.recv(1.0).arbitration_id == 0x200 and b.recv(0) is None


def test_malformed_packets_are_counted_and_dropped(make_bus: MakeBus) -> None:
    b = make_bus()
    good = encode_frame(frame(5), 1)
    bad = [b"", b"short", bytes([0x00]) + good[1:], good + b"x", good[:-1],
           HEADER.pack(MAGIC, 0, 9, 9, 0x10, 1) + bytes(9),          # classic DLC 9
           HEADER.pack(MAGIC, 2, 2, 2, 0x10, 1) + bytes(2),          # remote frame with data
           HEADER.pack(MAGIC, 0x40, 0, 0, 0x10, 1),                  # unknown flag
           HEADER.pack(MAGIC, 0, 0, 0, 0x10, 0),                     # no send time
           bytes(200)]                                                # longer than any frame (read truncated)
    raw = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    raw.connect(str(b._path))
    for p in bad:
        raw.send(p)
    raw.send(good)
    got = b.recv(2.0)
    assert got is not None and got.data == frame(5).data
    assert b.frames_malformed == len(bad) and b.recv(0) is None
    raw.close()
    assert b.recv(0) is None and b._in == {}     # the raw member's end is seen and its connection closed
    for p in bad[1:-1]:
        with pytest.raises(MalformedFrame):
            decode_frame(p, CH)


def test_shutdown_removes_the_member_and_the_last_one_the_directory(make_bus: MakeBus, bus_dir: str) -> None:
    a, b = make_bus(), make_bus()
    d = channel_dir(CH, bus_dir)
    assert sorted(p.name for p in d.iterdir()) == sorted([a._name, b._name])
    a.shutdown()
    assert [p.name for p in d.iterdir()] == [b._name]
    b.send(frame(1))                 # a left: forgotten, not waited for
    assert b.member_count == 0 and b.frames_dropped == 0
    b.shutdown()
    assert not d.exists()
    with pytest.raises(can.CanOperationError):
        b.send(frame(2))


def test_a_stuck_member_costs_one_timeout_then_its_frames_are_dropped_and_counted(
        make_bus: MakeBus, bus_dir: str, caplog: pytest.LogCaptureFixture) -> None:
    a, b = make_bus(send_timeout_s=0.05, sndbuf_bytes=16384), make_bus()
    stuck = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)   # listens, never accepts nor reads
    stuck.bind(str(channel_dir(CH, bus_dir) / "stuck.sock"))
    stuck.listen(1)
    got = []
    for i in range(500):
        a.send(frame(i))
        got.append(int.from_bytes(b.recv(1.0).data, "little"))    # b reads as it goes: never full
    assert a.member_count == 2 and a.send_waits == 1 and 0 < a.frames_dropped < 500
    assert got == list(range(500)) and b.recv(0) is None
    conn, _ = stuck.accept()           # it catches up: reads everything queued for it
    conn.setblocking(False)
    queued = [decode_frame(p, CH) for p in iter(lambda: _recv_or_none(conn), None)]
    assert [int.from_bytes(m.data, "little") for m in queued] == list(range(len(queued)))   # a prefix, in order
    assert len(queued) + a.frames_dropped == 500
    a.send(frame(500))                 # then gets frames again
    assert int.from_bytes(decode_frame(conn.recv(100), CH).data, "little") == 500
    assert "reads again" in caplog.text
    conn.close()
    a.shutdown()
    assert f"{a.frames_dropped} frame(s) sent were dropped for stuck members (stuck.sock: {a.frames_dropped})" \
        in caplog.text
    stuck.close()


def _recv_or_none(conn: socket.socket) -> bytes | None:
    try:
        return conn.recv(100)
    except BlockingIOError:
        return None


def test_dead_members_are_detected_not_waited_for(make_bus: MakeBus, bus_dir: str) -> None:
    a = make_bus(send_timeout_s=60.0)
    d = channel_dir(CH, bus_dir)
    seen, unseen = member(bus_dir, "idle"), None
    try:
        wait_joined(seen)
        a.send(frame(1))                     # connected to `seen`
        unseen = member(bus_dir, "idle")     # joins; killed before `a` sends to it
        wait_joined(unseen)
        for p in (seen, unseen):
            p.send_signal(signal.SIGKILL)
            p.wait(timeout=30)
        a.send(frame(2))                     # `seen`: reset connection; `unseen`: its stale file, removed
        a.send(frame(3))                     # `seen`'s stale file, looked at again and removed
        assert a.frames_dropped == 0 and a.member_count == 0 and a.members_lost >= 2
        assert [p.name for p in d.iterdir()] == [a._name]
    finally:
        for p in (seen, unseen):
            if p is not None:
                end_process(p)


def test_fifty_thousand_frames_from_two_processes_to_a_slow_receiver_lose_nothing(bus_dir: str) -> None:
    """Two sender processes, 25,000 frames each, as fast as they can; this process reads slowly (a pause every 500
    frames), with small send buffers (16 KiB) so the senders do wait: nothing dropped, each sender's frames in
    order."""
    rx = IpcBus(CH, directory=bus_dir)
    n = 25_000
    procs = [member(bus_dir, "send", str(n), str(s), "16384") for s in (1, 2)]
    try:
        nxt = {1: 0, 2: 0}
        while sum(nxt.values()) < 2 * n:
            msg = rx.recv(timeout=60.0)
            assert msg is not None, nxt
            sender, i = msg.data[0], int.from_bytes(msg.data[1:5], "little")
            assert i == nxt[sender], (sender, i, nxt[sender])
            nxt[sender] += 1
            if sum(nxt.values()) % 500 == 0:
                select.select([], [], [], 0.002)   # a slow reader (not a synchronisation)
        reports = [json.loads(p.communicate(timeout=60)[0].strip().splitlines()[-1]) for p in procs]
    finally:
        for p in procs:
            end_process(p)
        rx.shutdown()
    assert all(r["sent"] == n and r["dropped"] == 0 for r in reports), reports
    assert sum(r["waits"] for r in reports) > 0, reports    # flow control was exercised
    assert rx.frames_received == 2 * n and rx.frames_malformed == 0


def test_spec_and_python_can_entry_point(bus_dir: str) -> None:
    assert parse_can_spec("ipc:sea-hil") == ("ipc", "sea-hil")
    assert load_config(overrides={"can": {"interface": "ipc:sea-hil"}}).can.interface == "ipc:sea-hil"
    assert bus_specs("ipc:limb", 2) == ["ipc:limb0", "ipc:limb1"]
    for bad in ("ipc:", "ipc:.hidden", "ipc:a/b", "ipc:" + "x" * 41):
        with pytest.raises(ConfigError, match="ipc channel"):
            parse_can_spec(bad)
    a = can.Bus(interface="ipc", channel=CH, directory=bus_dir)
    b = IpcBus(CH, directory=bus_dir)
    try:
        assert isinstance(a, IpcBus)
        a.send(frame(3))
        assert b.recv(1.0).data[0] == 3
    finally:
        a.shutdown()
        b.shutdown()
    bus = open_bus("ipc:sea-hil-test-open-" + str(os.getpid()), fd=True)
    try:
        assert isinstance(bus, IpcBus) and bus.protocol == can.CanProtocol.CAN_FD
    finally:
        bus.shutdown()
