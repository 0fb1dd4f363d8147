"""`sea-hil plant` on a real SocketCAN vcan0, driven with can-utils: `cansend` voltage frames in, `candump -L` out.

Runs only where vcan0 is up (conftest skips otherwise), e.g.:
    scripts/with-vcan -- python -m pytest -q tests/socketcan/test_driver_vcan.py
Generous but bounded deadlines (UML syscalls are slow); the plant process is ended in `finally`, candump by the
conftest fixture.
"""
from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import can

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import CMD_BITS, CMD_MASK, DriverState, FeedbackAngle, Heartbeat, VoltageCmd

NODE = 1
REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60.0
MOVE_TIMEOUT_S = 60.0
SEND_EVERY_S = 0.02
WATCHDOG_S = "5"   # one cansend can take longer than 0.5 s in a loaded guest: the drive must not time out between
PLANT_DURATION_S = "600"   # outlives both deadlines (ended in `finally`): a slow guest must not end it first
MOVED_RAD = 0.01  # 100 LSB of the DBC theta signal


def _end(proc: subprocess.Popen | None) -> None:
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=10.0)


def cansend_arg(codec: SeaCodec, cmd: VoltageCmd) -> str:
    msg = codec.encode(cmd)
    return f"{msg.arbitration_id:03X}#{bytes(msg.data).hex().upper()}"


def _take(codec: SeaCodec, raw: object, angles: list[float], states: set[DriverState]) -> bool:
    """Decode one candump frame of the plant into `angles`/`states`; True once the hip moved while RUNNING."""
    msg = can.Message(arbitration_id=raw.arbitration_id, data=raw.data, is_extended_id=False)  # type: ignore
    try:
        frame = codec.decode(msg)
    except MalformedFrame as err:
        raise AssertionError(f"candump saw a frame the DBC rejects: {raw}: {err}") from err
    if isinstance(frame, FeedbackAngle):
        angles.append(frame.theta_rad[0])
        return abs(angles[-1] - angles[0]) > MOVED_RAD and DriverState.RUNNING in states
    if isinstance(frame, Heartbeat):
        states.add(frame.state)
    return False


def test_plant_answers_cansend_voltage_frames_seen_by_candump(tmp_path: Path, vcan_channel: str,
                                                               cansend: Callable[[str], None],
                                                               start_candump: Callable[..., object]) -> None:
    codec = SeaCodec([NODE])
    # only FEEDBACK_ANGLE and HEARTBEAT (1.01 kHz instead of 3.01 kHz), so a slow guest keeps up with the dump
    db = load_database()
    wanted = [(db.get_message_by_name(name).frame_id & CMD_MASK) | NODE << CMD_BITS
              for name in ("FEEDBACK_ANGLE", "HEARTBEAT")]
    dump = start_candump(filters=",".join(f"{can_id:03X}:7FF" for can_id in wanted))
    log_path = tmp_path / "plant.log"
    plant = None
    with log_path.open("w") as plant_log:
        try:
            plant = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "plant", "--can",
                                      f"socketcan:{vcan_channel}", "--node", str(NODE), "--duration", PLANT_DURATION_S,
                                      "--watchdog", WATCHDOG_S], cwd=REPO, stdout=plant_log, stderr=subprocess.STDOUT)
            angles: list[float] = []
            states: set[DriverState] = set()
            seq, next_send = 0, None
            deadline = time.monotonic() + START_TIMEOUT_S
            moved = False
            while time.monotonic() < deadline and not moved:
                now = time.monotonic()
                if angles and (next_send is None or now >= next_send):  # feedback flows: stream commands
                    if next_send is None:
                        deadline = now + MOVE_TIMEOUT_S
                    cansend(cansend_arg(codec, VoltageCmd(NODE, (2.0, 0.0), seq)))  # no soft limit within 1 s
                    seq, next_send = (seq + 1) & 0xFF, time.monotonic() + SEND_EVERY_S
                # the newest angle and every heartbeat: a slow guest decodes slower than the plant sends (1 kHz)
                frames = dump.newest_frames(timeout_s=SEND_EVERY_S, every=frozenset({f"{wanted[1]:03X}"}))
                if not frames:
                    assert plant.poll() is None, f"plant exited early: {log_path.read_text()}"
                for raw in frames:
                    moved = _take(codec, raw, angles, states) or moved
            assert angles, f"no feedback frame on {vcan_channel} within {START_TIMEOUT_S} s"
            assert DriverState.RUNNING in states, f"heartbeats never showed RUNNING (saw {states})"
            assert abs(angles[-1] - angles[0]) > MOVED_RAD, f"hip did not move: {angles[0]} -> {angles[-1]}"
        finally:
            _end(plant)
