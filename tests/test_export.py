"""`sea-hil export`: candump -L and ASC round trips through python-can's readers, CSV through pandas."""
from __future__ import annotations

from pathlib import Path

import can
import pandas as pd
import pytest

from sea_hil.cli import main
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback, VoltageCmd
from sea_hil.protocol.payloads import StatePayload, encode
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.export import BASE_COLUMNS, csv_name, export_can
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.recorder.zenoh_tap import ZenohTap

T0_NS = 1_700_000_000_123_456_000


def _frames() -> list[can.Message]:
    codec = SeaCodec()
    out = []
    for k in range(1, 6):
        fb = Feedback(1, k, k * 1000, (0.1 * k, -0.2), (0.3, 0.4), (1e-3, -2e-3), (0.01, 0.02))
        out += [*codec.encode_feedback(fb), codec.encode(VoltageCmd(1, (1.5, -2.0), k))]
    out.append(can.Message(arbitration_id=0x1ABCDE, data=bytes([1, 2, 3]), is_extended_id=True))   # not in the DBC
    for i, m in enumerate(out):
        m.timestamp = (T0_NS + i * 250_000) * 1e-9
    return out


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Path, list[can.Message]]:
    frames, path = _frames(), tmp_path / "run.mcap"
    tap, ztap = CanTap(), ZenohTap()
    with SessionRecorder(path) as rec:
        for m in frames:
            for r in tap.records(RawFrame.of(round(m.timestamp * 1e9), m)):
                rec.record(*r)
        state = encode(StatePayload(3, 99, 5_000_000, (0.1, 0.2), (0.3, 0.4), (1e-3, 2e-3), (0.05, -0.06)))
        for r in ztap.records("sea/limb1/state", state, T0_NS + 10**6):
            rec.record(*r)
    return path, frames


def _same_frames(got: list[can.Message], want: list[can.Message], abs_s: float) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert (g.arbitration_id, g.is_extended_id, g.dlc, bytes(g.data)) == \
            (w.arbitration_id, w.is_extended_id, w.dlc, bytes(w.data))
        assert g.timestamp == pytest.approx(w.timestamp, abs=abs_s)


def test_candump_log_round_trips_through_python_can(recording, tmp_path: Path):
    path, frames = recording
    out = tmp_path / "run.log"
    assert main(["export", str(path), "--candump", str(out), "--channel", "vcan0"]) == 0
    got = list(can.CanutilsLogReader(out))
    _same_frames(got, frames, abs_s=1e-6)
    assert all(m.channel == "vcan0" for m in got)
    assert out.read_text().splitlines()[0].startswith(f"({T0_NS * 1e-9:.6f}) vcan0 023#")


def test_asc_round_trips_through_python_can(recording, tmp_path: Path):
    path, frames = recording
    out = tmp_path / "run.asc"
    assert export_can(read_session(path), out, "asc") == len(frames)
    got = list(can.ASCReader(out, relative_timestamp=False))
    _same_frames(got, frames, abs_s=2e-3)   # ASC keeps the start time to the millisecond


def test_csv_per_channel_loads_with_pandas_with_the_documented_columns(recording, tmp_path: Path):
    path, frames = recording
    assert main(["export", str(path), "--csv", str(tmp_path / "csv")]) == 0
    files = {p.name for p in (tmp_path / "csv").iterdir()}
    assert {csv_name(t) for t in ("/can/raw", "/can/feedback", "/can/command", "/zenoh/state", "/joint_states")} \
        <= files and "zenoh_voltage.csv" not in files        # empty channels are not written
    raw = pd.read_csv(tmp_path / "csv" / "can_raw.csv")
    assert list(raw.columns[:3]) == list(BASE_COLUMNS) and len(raw) == len(frames)
    assert raw["can_id"].tolist() == [m.arbitration_id for m in frames]
    fb = pd.read_csv(tmp_path / "csv" / "can_feedback.csv")
    assert {"node_id", "seq", "t_us", "theta1_rad", "nut_vel1_m_s", "nut_vel2_m_s"} <= set(fb.columns)
    assert fb["nut_vel2_m_s"].dropna().round(4).tolist() == [0.02] * 5
    js = pd.read_csv(tmp_path / "csv" / "joint_states.csv")
    assert js.loc[0, "joints.1.name"] == "knee" and js.loc[0, "joints.1.position"] == pytest.approx(0.2)
    assert js.loc[0, "sequence"] == 3 and js.loc[0, "timestamp.sec"] == (T0_NS + 10**6) // 10**9


def test_export_without_an_output_is_a_clear_error(recording, capsys):
    assert main(["export", str(recording[0])]) == 2
    assert "nothing to export" in capsys.readouterr().err
