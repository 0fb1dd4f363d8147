"""`sea-hil export --ros2` on a real-time style recording (log time = wall clock; classic CAN and CAN FD: header
stamps are the drive's sample time) and on bad input (truncated, foreign, not MCAP, an existing directory, a failure
while writing: one line, exit 2, nothing left behind). Recordings made here with the recorder's own taps."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import can
import pytest
from mcap.writer import Writer
from ros2_bag import export, t_ns

from sea_hil.cli import main
from sea_hil.config.loader import load_config
from sea_hil.errors import RecordingError
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Feedback, Heartbeat, VoltageCmd
from sea_hil.protocol.cia402_od import EMCY_CODES
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.ros2.convert import DIAGNOSTICS, Converter

REPO = Path(__file__).resolve().parent.parent
T0_NS = 1_700_000_000_000_000_000


def _wall_clock_recording(path: Path, fd: bool) -> list[tuple[int, can.Message]]:
    """A real-time style recording (log time = wall clock, the tap's default) of 5 drive samples, 1 ms apart, the
    drive's clock at 7 ms when the recording starts, plus one heartbeat; no config attachment. -> (t_ns, frame)."""
    codec = SeaCodec(fd=fd)
    frames = []
    for k in range(5):
        fb = Feedback(1, k, 7000 + k * 1000, (0.1 * k, -0.2), (0.3, 0.4 * k), (1e-3, -2e-3), (0.01, 0.02))
        batch = [*codec.encode_feedback(fb), codec.encode(VoltageCmd(1, (1.5, -2.0), k))]
        frames += [(T0_NS + k * 1_000_000 + i * 20_000, m) for i, m in enumerate(batch)]
    frames.append((T0_NS + 4_500_000, codec.encode(Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 0, 0, 0))))
    tap = CanTap()
    with SessionRecorder(path) as rec:
        for t, m in frames:
            for r in tap.records(RawFrame.of(t, m)):
                rec.record(*r)
    return frames


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "can-fd"])
def test_a_wall_clock_recording_stamps_the_sample_time(tmp_path: Path, fd: bool):
    frames = sorted(_wall_clock_recording(tmp_path / "rt.mcap", fd), key=lambda f: f[0])
    bag = export(tmp_path / "rt.mcap", tmp_path / "bag")
    topic = "/from_can_bus_fd" if fd else "/from_can_bus"
    msgs = bag["messages"]
    assert set(msgs) == {topic, "/joint_states", "/diagnostics", "/rosout"}
    assert bag["channels"][topic][0] == ("ros2_socketcan_msgs/msg/FdFrame" if fd else "can_msgs/msg/Frame")
    got = msgs[topic]
    assert len(got) == len(frames)
    for (t, m), (log, _, _, f) in zip(frames, got, strict=True):
        assert log == t and f.id == m.arbitration_id
        assert bytes(f.data)[:m.dlc if not fd else None] == bytes(m.data)
        if fd:
            assert f.len == len(m.data)
        k = (log - T0_NS) // 1_000_000                       # the sample the frame belongs to
        assert t_ns(f.header.stamp) == (7 + k) * 1_000_000   # the drive's clock, not the wall clock
    js = msgs["/joint_states"]
    assert [t_ns(j.header.stamp) for *_, j in js] == [(7 + k) * 1_000_000 for k in range(5)]
    for k, (*_, j) in enumerate(js):                               # the frames' resolution: 1e-4 rad (FD: finer)
        assert list(j.position) == pytest.approx([0.1 * k, -0.2], abs=1e-4)
    assert all(list(j.effort) == [] for *_, j in js)           # no config in the file: no spring torque
    hb, final = [d for *_, d in msgs["/diagnostics"]]           # the heartbeat, the recorder's final counters
    assert final.status[0].name == "recorder" and msgs["/diagnostics"][-1][0] == frames[-1][0]
    assert (hb.status[0].name, hb.status[0].level, t_ns(hb.header.stamp)) == ("driver1", 0, 11_000_000)
    (log,) = [r for *_, r in msgs["/rosout"]]                  # the driver going RUNNING, at its drive's time
    assert (log.name, log.level, t_ns(log.stamp)) == ("driver1", 20, 11_000_000) and "RUNNING" in log.msg


def _one_line_error(capsys, needle: str) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def _nothing_left(parent: Path, name: str) -> None:
    assert not [p for p in parent.iterdir() if p.name.startswith((name, f".{name}."))]


def test_bad_input_is_one_line_exit_2_and_leaves_nothing(tmp_path: Path, capsys):
    good = tmp_path / "good.mcap"
    _wall_clock_recording(good, False)
    whole = good.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(whole[: len(whole) - 40])     # the footer and closing magic lost
    assert main(["export", str(tmp_path / "cut.mcap"), "--ros2", str(tmp_path / "out")]) == 2
    _one_line_error(capsys, "truncated")
    _nothing_left(tmp_path, "out")

    foreign = tmp_path / "other.mcap"
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="someone else")
        ch = w.register_channel("/chatter", "json", w.register_schema("Chatter", "jsonschema", b"{}"))
        w.add_message(ch, log_time=1, data=b"{}", publish_time=1)
        w.finish()
    assert main(["export", str(foreign), "--ros2", str(tmp_path / "out")]) == 2
    _one_line_error(capsys, "not a sea-hil recording")
    export(good, tmp_path / "bag")
    capsys.readouterr()
    bag_file = tmp_path / "bag" / "bag_0.mcap"            # a ROS 2 bag is not a sea-hil recording either
    assert main(["export", str(bag_file), "--ros2", str(tmp_path / "out")]) == 2
    _one_line_error(capsys, "not a sea-hil recording")
    (tmp_path / "text.mcap").write_text("hello\n")
    assert main(["export", str(tmp_path / "text.mcap"), "--ros2", str(tmp_path / "out")]) == 2
    _one_line_error(capsys, "not an MCAP file")
    _nothing_left(tmp_path, "out")

    (tmp_path / "out").mkdir()
    assert main(["export", str(good), "--ros2", str(tmp_path / "out")]) == 2
    _one_line_error(capsys, "already exists")
    assert list((tmp_path / "out").iterdir()) == []


def test_a_failure_while_writing_leaves_nothing(tmp_path: Path, capsys, monkeypatch):
    from sea_hil.ros2 import bag as bag_module
    _wall_clock_recording(tmp_path / "good.mcap", False)
    real, calls = bag_module.BagWriter.write, []

    def failing(self: Any, m: Any) -> None:
        calls.append(1)
        if len(calls) == 10:
            raise RecordingError("disk full (simulated)")
        real(self, m)

    monkeypatch.setattr(bag_module.BagWriter, "write", failing)
    assert main(["export", str(tmp_path / "good.mcap"), "--ros2", str(tmp_path / "b")]) == 2
    _one_line_error(capsys, "disk full (simulated)")
    _nothing_left(tmp_path, "b")
    assert len(calls) == 10


def test_the_bench_script_times_the_cli_on_a_recording(tmp_path: Path):
    _wall_clock_recording(tmp_path / "rt.mcap", False)
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, "-m", "bench.bench_ros2_export", "--quick", "--session",
                           str(tmp_path / "rt.mcap"), "--json", str(out)], cwd=REPO, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    (rec,) = json.loads(out.read_text())
    assert (rec["figure"], rec["runs"], rec["unit"]) == ("ros2", 1, "s") and rec["median"] > 0
    assert rec["command"].startswith("python -m bench.bench_ros2_export") and rec["details"][0]["bag_bytes"] > 0


def test_a_cia402_recordings_driver_diagnostics_come_from_statuswords() -> None:
    """A cia402 session (nodes 7 and 8: COB-IDs whose low five bits are the DBC's HEARTBEAT command): `/diagnostics`
    has one driver status per statusword TPDO (FAULT with the EMCY's flag, then cleared), none for the TPDO 2 that
    the DBC would read as driver 20's FAULT heartbeat (position 2 urad, velocity 0), and every frame is still a
    can_msgs/Frame."""
    tpdo2 = struct.pack("<ii", 2, 0)
    hb = SeaCodec(fd=None).decode_raw(0x287, tpdo2, 8)           # the hazard: the DBC's reading of it
    assert isinstance(hb, Heartbeat) and (hb.node_id, hb.state) == (20, DriverState.FAULT)
    frames = [(0x187, bytes([0x27, 0x00, 0xFF])), (0x287, tpdo2),
              (0x87, struct.pack("<HB5x", EMCY_CODES[ErrorFlags.POSITION_LIMIT], 0x01)),
              (0x187, bytes([0x08, 0x00, 0xFF])), (0x187, bytes([0x27, 0x00, 0xFF]))]
    raw = [RecordedMessage(k * 1_000_000, k * 1_000_000, {"can_id": c, "dlc": len(d), "data_hex": d.hex(),
                                                           "direction": "rx", "is_extended": False, "node_id": 7}, k)
           for k, (c, d) in enumerate(frames)]
    cfg = load_config(overrides={"can": {"profile": "cia402", "cia402": {"node_ids": [7, 8]}}})
    out = list(Converter(SessionData(messages={"/can/raw": raw}), cfg).can_frames())
    diags = [m.message["status"][0] for m in out if m.type_name == DIAGNOSTICS]
    assert [(d["name"], d["message"], d["level"]) for d in diags] == [
        ("driver7", "RUNNING, error flags none", 0), ("driver7", "FAULT, error flags POSITION_LIMIT", 2),
        ("driver7", "RUNNING, error flags none", 0)]
    assert sum(m.type_name != DIAGNOSTICS for m in out) == len(frames)
