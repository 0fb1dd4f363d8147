"""Export a session recording to the tools people already use (`sea-hil export`, docs/recording.md "Export").

* `export_can(data, path, fmt)`: every `/can/raw` frame, in log-time order, through python-can's writers: `candump`
  (`candump -L` log format, replayable with `canplayer -I FILE`) or `asc` (Vector ASCII). Timestamps are the
  frames' MCAP log times (wall clock, or in lockstep the drive's sample time from 0).
* `export_csv(data, directory)`: one CSV per non-empty channel (`/zenoh/state` -> `zenoh_state.csv`) with flat
  columns `log_time_ns, publish_time_ns, sequence`, then the payload's fields in first-seen order; nested fields of
  the Foxglove channels are flattened with dots and list indices (`joints.0.position`, `timestamp.sec`). A field a
  message lacks is an empty cell.
* A cia402 session (`[can] profile = "cia402"` in the recording's attached config): its frames decoded with the
  drive's object dictionary names (`sea_hil.protocol.cia402_decode`, the source of the EDS): `export_csv`'s
  `can_raw.csv` gains the columns `canopen_kind` and `canopen` ("TPDO2 node 1: position_actual_value=..."), and
  `export_canopen(data, path)` writes one CSV of every frame with its meaning (`sea-hil export --candump FILE.log`
  writes it beside the log as FILE.canopen.csv; the log itself stays a plain, replayable candump -L file).
"""
from __future__ import annotations

import csv
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import can

from sea_hil.errors import RecordingError
from sea_hil.protocol.cia402_decode import Cia402Decoder
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.recorder.session_config import canopen_decoder

CAN_FORMATS = ("candump", "asc")
BASE_COLUMNS = ("log_time_ns", "publish_time_ns", "sequence")
CANOPEN_COLUMNS = ("time_s", "can_id", "dlc", "data_hex", "node_id", "kind", "canopen")


def canopen_rows(data: SessionData, decoder: Cia402Decoder) -> Iterator[tuple[RecordedMessage, dict[str, Any]]]:
    """Each `/can/raw` message with its decoded columns (`kind`, `canopen`), in recording order (the decoder follows
    the nodes' PDO configuration as the bus changed it)."""
    for m in data.messages.get("/can/raw", []):
        p = m.payload
        try:
            d = decoder.decode(int(p["can_id"]), bytes.fromhex(p["data_hex"]),
                               extended=bool(p.get("is_extended", False)))
        except (KeyError, TypeError, ValueError) as err:
            raise RecordingError(f"/can/raw message at {m.log_time_ns} ns is not a frame: {err}") from err
        yield m, {"kind": d.kind, "canopen": d.text}


def export_canopen(data: SessionData, path: str | os.PathLike[str], decoder: Cia402Decoder) -> int:
    """Every recorded frame of a cia402 session with its meaning, one CSV row each (`CANOPEN_COLUMNS`; time in
    seconds as in the candump log); -> rows written."""
    n = 0
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CANOPEN_COLUMNS)
        for m, d in canopen_rows(data, decoder):
            p = m.payload
            w.writerow((f"{m.log_time_ns * 1e-9:.6f}", f"0x{int(p['can_id']):03X}", p["dlc"], p["data_hex"],
                        p.get("node_id", ""), d["kind"], d["canopen"]))
            n += 1
    return n


def canopen_path(log: str | os.PathLike[str]) -> Path:
    """Where `sea-hil export --candump FILE.log` puts a cia402 session's decoded frames: FILE.canopen.csv."""
    return Path(log).with_suffix(".canopen.csv")


def can_messages(data: SessionData, channel: str | int | None = None) -> Iterator[can.Message]:
    """The recorded frames (`/can/raw`) as python-can messages, in log-time order."""
    for m in data.messages.get("/can/raw", []):
        p = m.payload
        try:
            payload = bytes.fromhex(p["data_hex"])
            yield can.Message(timestamp=m.log_time_ns * 1e-9, arbitration_id=int(p["can_id"]),
                              is_extended_id=bool(p.get("is_extended", False)), dlc=int(p["dlc"]), data=payload,
                              is_fd=bool(p.get("is_fd", False)), bitrate_switch=bool(p.get("is_fd", False)),
                              is_rx=p.get("direction", "rx") == "rx", channel=channel)
        except (KeyError, TypeError, ValueError) as err:
            raise RecordingError(f"/can/raw message at {m.log_time_ns} ns is not a frame: {err}") from err


def export_can(data: SessionData, path: str | os.PathLike[str], fmt: str, channel: str | int | None = None) -> int:
    """Write every recorded frame to `path` as `fmt` (`candump` or `asc`); -> frames written."""
    if fmt == "candump":
        writer: can.io.generic.MessageWriter = can.CanutilsLogWriter(path, channel=str(channel or "vcan0"))
    elif fmt == "asc":
        writer = can.ASCWriter(path, channel=channel if isinstance(channel, int) else 1)
    else:
        raise RecordingError(f"CAN export format must be one of {CAN_FORMATS}, got {fmt!r}")
    n = 0
    try:
        for msg in can_messages(data, channel if fmt == "candump" else None):
            writer.on_message_received(msg)
            n += 1
    finally:
        writer.stop()
    return n


def flatten(payload: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested objects and lists -> one level with `a.b` / `a.0.b` keys."""
    out: dict[str, Any] = {}
    for k, v in payload.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, f"{key}."))
        elif isinstance(v, list):
            out.update(flatten({str(i): x for i, x in enumerate(v)}, f"{key}."))
        else:
            out[key] = v
    return out


def csv_name(topic: str) -> str:
    """`/zenoh/state` -> `zenoh_state.csv`."""
    return topic.strip("/").replace("/", "_") + ".csv"


def _rows(msgs: list[RecordedMessage]) -> tuple[list[str], list[dict[str, Any]]]:
    columns: dict[str, None] = dict.fromkeys(BASE_COLUMNS)
    rows = []
    for m in msgs:
        row = {"log_time_ns": m.log_time_ns, "publish_time_ns": m.publish_time_ns, "sequence": m.sequence,
               **flatten(m.payload)}
        columns.update(dict.fromkeys(row))
        rows.append(row)
    return list(columns), rows


def export_csv(data: SessionData, directory: str | os.PathLike[str]) -> list[Path]:
    """One CSV per non-empty channel in `directory` (created); -> the files written."""
    out = Path(directory)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(f"cannot create {out}: {err}") from err
    written = []
    decoder = canopen_decoder(data)
    for topic, msgs in sorted(data.messages.items()):
        if not msgs:
            continue
        columns, rows = _rows(msgs)
        if topic == "/can/raw" and decoder is not None:   # a cia402 session: each frame's meaning beside it
            columns += ["canopen_kind", "canopen"]
            for row, (_, d) in zip(rows, canopen_rows(data, decoder), strict=True):
                row["canopen_kind"], row["canopen"] = d["kind"], d["canopen"]
        path = out / csv_name(topic)
        with path.open("w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=columns, restval="", extrasaction="raise")
            w.writeheader()
            w.writerows({k: _cell(v) for k, v in r.items()} for r in rows)
        written.append(path)
    return written


def _cell(v: Any) -> Any:
    return "" if v is None else v   # null (a non-finite float) -> empty cell (NaN in pandas)
