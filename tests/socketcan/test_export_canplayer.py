"""`sea-hil export --candump` writes a log that can-utils' `canplayer` replays onto vcan0, and `candump` sees the
frames, in order, exactly as recorded (issue 18)."""
from __future__ import annotations

import shutil
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import can
import pytest
from socketcan_helpers import PROCESS_TIMEOUT_S

from sea_hil.cli import main
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback, VoltageCmd
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.writer import SessionRecorder

PROBE_ID = 0x7FD   # candump is listening once it printed this (not a sea-hil id)
DEADLINE_S = 10.0


def _record(path: Path) -> list[can.Message]:
    """A short recording: 10 samples of feedback (3 frames) + VOLTAGE_CMD, 1 ms apart, as the recorder writes it."""
    codec, tap, frames = SeaCodec(), CanTap(), []
    for k in range(1, 11):
        fb = Feedback(1, k, k * 1000, (0.01 * k, -0.2), (0.3, 0.4), (1e-3, -2e-3), (0.01, 0.02))
        frames += [*codec.encode_feedback(fb), codec.encode(VoltageCmd(1, (0.1 * k, -2.0), k))]
    with SessionRecorder(path) as rec:
        for i, m in enumerate(frames):
            for r in tap.records(RawFrame.of(1_700_000_000_000_000_000 + i * 250_000, m)):
                rec.record(*r)
    return frames


def test_canplayer_replays_an_exported_log_onto_vcan0(tmp_path: Path, start_candump: Callable[..., object],
                                                      open_can_bus: Callable[..., can.BusABC],
                                                      vcan_channel: str) -> None:
    canplayer = shutil.which("canplayer")
    if canplayer is None:
        pytest.skip("canplayer not installed (apt-get install can-utils)")
    frames = _record(tmp_path / "run.mcap")
    log = tmp_path / "run.log"
    assert main(["export", str(tmp_path / "run.mcap"), "--candump", str(log), "--channel", vcan_channel]) == 0
    dump = start_candump()
    probe, sender = can.Message(arbitration_id=PROBE_ID, data=b"\x01", is_extended_id=False), open_can_bus()
    deadline = time.monotonic() + DEADLINE_S
    seen = None
    while (seen is None or seen.arbitration_id != PROBE_ID) and time.monotonic() < deadline:
        sender.send(probe)          # candump may not have bound its socket yet: probe until it prints
        seen = dump.next_frame(timeout_s=0.2)
    assert seen is not None and seen.arbitration_id == PROBE_ID, "candump never listened"
    subprocess.run([canplayer, "-I", str(log)], check=True, stdin=subprocess.DEVNULL, capture_output=True,
                   timeout=PROCESS_TIMEOUT_S)
    got = []
    while len(got) < len(frames):
        f = dump.next_frame(timeout_s=DEADLINE_S)
        assert f is not None, f"candump saw {len(got)} of {len(frames)} replayed frames"
        if f.arbitration_id != PROBE_ID:
            got.append(f)
    assert [(f.channel, f.arbitration_id, f.is_extended_id, f.data) for f in got] == \
        [(vcan_channel, m.arbitration_id, False, bytes(m.data)) for m in frames]
