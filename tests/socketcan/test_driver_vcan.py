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

from sea_hil.protocol.can_codec import DriverState, FeedbackAngle, Heartbeat, SeaCodec, VoltageCmd
from sea_hil.errors import MalformedFrame

NODE = 1
REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60.0
MOVE_TIMEOUT_S = 60.0
SEND_EVERY_S = 0.02
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


def test_plant_answers_cansend_voltage_frames_seen_by_candump(tmp_path: Path, vcan_channel: str,
                                                               cansend: Callable[[str], None],
                                                               start_candump: Callable[..., object]) -> None:
    codec = SeaCodec([NODE])
    dump = start_candump()
    log_path = tmp_path / "plant.log"
    plant = None
    with log_path.open("w") as plant_log:
        try:
            plant = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "plant", "--can",
                                      f"socketcan:{vcan_channel}", "--node", str(NODE), "--duration", PLANT_DURATION_S,
                                      "--watchdog", "0.5"], cwd=REPO, stdout=plant_log, stderr=subprocess.STDOUT)
            angles: list[float] = []
            states: set[DriverState] = set()
            seq, next_send = 0, None
            deadline = time.monotonic() + START_TIMEOUT_S
            while time.monotonic() < deadline:
                now = time.monotonic()
                if angles and (next_send is None or now >= next_send):  # feedback flows: stream commands
                    if next_send is None:
                        deadline = now + MOVE_TIMEOUT_S
                    cansend(cansend_arg(codec, VoltageCmd(NODE, (2.0, 0.0), seq)))  # no soft limit within 1 s
                    seq, next_send = (seq + 1) & 0xFF, time.monotonic() + SEND_EVERY_S
                raw = dump.next_frame(timeout_s=SEND_EVERY_S)
                if raw is None:
                    assert plant.poll() is None, f"plant exited early: {log_path.read_text()}"
                    continue
                if raw.is_extended_id or raw.arbitration_id >> 5 != NODE:
                    continue
                msg = can.Message(arbitration_id=raw.arbitration_id, data=raw.data, is_extended_id=False)
                try:
                    frame = codec.decode(msg)
                except MalformedFrame as err:
                    raise AssertionError(f"candump saw a frame the DBC rejects: {raw}: {err}") from None
                if isinstance(frame, FeedbackAngle):
                    angles.append(frame.theta_rad[0])
                    if abs(angles[-1] - angles[0]) > MOVED_RAD and DriverState.RUNNING in states:
                        break
                elif isinstance(frame, Heartbeat):
                    states.add(frame.state)
            assert angles, f"no feedback frame on {vcan_channel} within {START_TIMEOUT_S} s"
            assert DriverState.RUNNING in states, f"heartbeats never showed RUNNING (saw {states})"
            assert abs(angles[-1] - angles[0]) > MOVED_RAD, f"hip did not move: {angles[0]} -> {angles[-1]}"
        finally:
            _end(plant)
