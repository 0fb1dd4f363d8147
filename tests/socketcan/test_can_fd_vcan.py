"""CAN FD on real SocketCAN (vcan0, MTU 72) and the kernel-side bus-timing equivalent (a tc shaper).

- sea-hil's FD frames (FEEDBACK_FD, VOLTAGE_CMD_FD) sent through `open_bus(..., fd=True)` are what candump prints,
  and `cantools decode` with protocol/sea.dbc decodes candump's output;
- the emulated driver answers VOLTAGE_CMD_FD with FEEDBACK_FD on vcan0 when `[can] fd = true`;
- `tc qdisc ... netem rate` on a vxcan pair holds frames back at the configured rate. On vcan with the module's
  default `echo=0` the kernel loops a frame back to local sockets before the qdisc, so a shaper there delays nothing
  local (docs/can-protocol.md, "Bus timing"); vxcan hands frames to its peer after the qdisc.
"""
from __future__ import annotations

import select
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from sea_hil.config.loader import load_config
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback, VoltageCmd
from sea_hil.protocol.canbus import open_bus

ROOT = Path(__file__).resolve().parents[2]
DEADLINE_S = 20.0


def _ensure_fd_mtu(channel: str) -> None:
    mtu = Path(f"/sys/class/net/{channel}/mtu")
    if int(mtu.read_text()) != 72:   # vcan's MTU can only change while it is down
        for args in (("down",), ("mtu", "72"), ("up",)):
            subprocess.run(["ip", "link", "set", channel, *args], check=True, capture_output=True, timeout=10)
    assert int(mtu.read_text()) == 72


def test_fd_frames_in_candump_decode_with_the_dbc(vcan_channel: str) -> None:
    _ensure_fd_mtu(vcan_channel)
    codec = SeaCodec(fd=True)
    frames = [*codec.encode_feedback(Feedback(1, 7, 1234, (0.5, -0.25), (1.0, -2.0), (0.001, -0.002), (0.1, -0.2))),
              codec.encode(VoltageCmd(1, (12.34567, -3.2), 7))]
    dump = subprocess.Popen(["candump", f"{vcan_channel},02A:7FF,028:7FF"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    bus = open_bus(f"socketcan:{vcan_channel}", fd=True)
    lines: list[str] = []
    try:
        deadline = time.monotonic() + DEADLINE_S
        while {"02A", "028"} - {ln.split()[1] for ln in lines} and time.monotonic() < deadline:
            for m in frames:      # candump may not have bound its socket yet: resend until it has printed both
                bus.send(m, timeout=5.0)
            while select.select([dump.stdout], [], [], 0.2)[0]:
                lines.append(dump.stdout.readline().rstrip("\n"))   # type: ignore[union-attr]
    finally:
        bus.shutdown()
        dump.terminate()
        dump.communicate(timeout=10)
    assert any(ln.split()[1:3] == ["02A", "[32]"] for ln in lines), lines      # a 32-byte CAN FD frame
    assert any(ln.split()[1:3] == ["028", "[08]"] for ln in lines), lines
    out = subprocess.run([sys.executable, "-m", "cantools", "decode", "-m", "0x1F", str(ROOT / "protocol/sea.dbc")],
                         input="\n".join(lines) + "\n", capture_output=True, text=True, timeout=60, check=True).stdout
    assert "FEEDBACK_FD(" in out and "t_us: 1234 us" in out and "omega2: -2.0 rad/s" in out
    assert "VOLTAGE_CMD_FD(" in out and "voltage1: 12.34567 V" in out


def test_driver_answers_fd_voltage_with_fd_feedback(vcan_channel: str) -> None:
    _ensure_fd_mtu(vcan_channel)
    cfg = load_config(None, {"can": {"fd": True, "node_ids": [9]}})
    node_bus, peer = open_bus(f"socketcan:{vcan_channel}", fd=True), open_bus(f"socketcan:{vcan_channel}", fd=True)
    codec = SeaCodec.for_bus(cfg.can, [9])
    node = PlantNode(cfg, node_bus, (9,))
    try:
        node.start(duration_s=None)
        got: Feedback | None = None
        deadline = time.monotonic() + DEADLINE_S
        while got is None and time.monotonic() < deadline:
            msg = peer.recv(timeout=1.0)
            if msg is None or msg.arbitration_id >> 5 != 9:
                continue
            frame = codec.decode(msg)
            if isinstance(frame, Feedback):
                assert msg.is_fd and msg.bitrate_switch and msg.dlc == 32
                peer.send(codec.encode(VoltageCmd(9, (1.5, -1.5), frame.seq)), timeout=5.0)
                if node.drivers[9].counters.commands:
                    got = frame
        assert got is not None and node.drivers[9].counters.commands > 0
        assert node.drivers[9].counters.rejected_frames == 0
    finally:
        node.close()
        node_bus.shutdown()
        peer.shutdown()


def test_tc_netem_rate_shapes_a_vxcan_pair() -> None:
    """100 classic 8-byte frames (a 16-byte can_frame + 1 byte overhead = 136 bits each) through `netem rate
    100kbit`: the peer cannot see them faster than 1.36 ms apart (a lower bound: UML timing is slow, never fast)."""
    a, b = f"vxa{uuid.uuid4().hex[:4]}", f"vxb{uuid.uuid4().hex[:4]}"
    mod = subprocess.run(["modprobe", "-d", "/run/seahil-modules", "vxcan"], capture_output=True, timeout=30)
    if mod.returncode and not Path("/sys/module/vxcan").exists():
        pytest.skip(f"no vxcan module: {mod.stderr!r}")
    subprocess.run(["ip", "link", "add", a, "type", "vxcan", "peer", "name", b], check=True, capture_output=True,
                   timeout=10)
    try:
        for dev in (a, b):
            subprocess.run(["ip", "link", "set", dev, "up"], check=True, capture_output=True, timeout=10)
        subprocess.run(["tc", "qdisc", "add", "dev", a, "root", "netem", "rate", "100kbit", "1"], check=True,
                       capture_output=True, timeout=10)
        tx, rx = open_bus(f"socketcan:{a}"), open_bus(f"socketcan:{b}")
        try:
            codec, n = SeaCodec(), 100
            for k in range(n):
                tx.send(codec.encode(VoltageCmd(1, (0.001 * k, 0.0), k)), timeout=5.0)
            stamps = []
            for _ in range(n):
                msg = rx.recv(timeout=DEADLINE_S)
                assert msg is not None
                stamps.append(msg.timestamp)
        finally:
            tx.shutdown()
            rx.shutdown()
        span_s = stamps[-1] - stamps[0]
        # VOLTAGE_CMD has 5 data bytes, but the qdisc sees the 16-byte can_frame: 17 * 8 bits per frame
        assert span_s >= 0.9 * (n - 1) * 17 * 8 / 100_000, span_s
    finally:
        subprocess.run(["ip", "link", "del", a], check=False, capture_output=True, timeout=10)
