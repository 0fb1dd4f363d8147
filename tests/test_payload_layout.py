"""protocol/payloads.toml (the machine-readable payload layout) against the code and the docs: the struct formats,
sizes, type ids and enum values it states are those `sea_hil.protocol.payloads` encodes and decodes (checked through
its public names only), and docs/zenoh-protocol.md's tables are the ones generated from it."""
from __future__ import annotations

import copy
import struct
from pathlib import Path
from typing import Any

import pytest

from sea_hil.protocol import payloads as pl
from sea_hil.protocol.payload_layout import STRUCT_CODE, load_layout, main, messages, render_tables, splice

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "zenoh-protocol.md"

# one payload per type with every field distinct, built through the public dataclasses
SAMPLES: dict[str, Any] = {
    "STATE": pl.StatePayload(11, 2**40 + 3, 5_000_000, (0.125, -0.25), (1.5, -2.5), (1e-4, -3e-4), (0.01, -0.02),
                             epoch=2**63 + 1),
    "SETPOINT": pl.SetpointPayload(12, 7, 99, (2e-3, -1e-3), (0.5, -0.75), pl.TriggerReason.TRACKING_BOUND,
                                   epoch=2**64 - 2),
    "VOLTAGE": pl.VoltagePayload(13, 8, 98, (3.25, -4.5), epoch=0x0123_4567_89AB_CDEF),
    "ACK": pl.AckPayload(14, 9, 97, 12, True, epoch=5),
    "EVENT_STATE": pl.EventStatePayload(15, 10, 6_000_000, (0.5, -0.5), (1.0, -1.0), (2e-4, -2e-4), (0.03, -0.03),
                                        41, pl.TriggerReason.ERROR_BOUND, 0xDEADBEEF, epoch=7),
}


def fields_format(fields: list[dict[str, Any]]) -> str:
    """The little-endian struct format a field list describes (e.g. `<Q8d`, runs of one type merged): the check
    that payloads.toml's `format` strings agree with its field lists."""
    out: list[tuple[int, str]] = []
    for f in fields:
        code = STRUCT_CODE[f["type"]]
        n = int(f.get("count", 1))
        if code.endswith("s"):          # bytesN is one item of N bytes
            out.append((1, code))
        elif out and out[-1][1] == code:
            out[-1] = (out[-1][0] + n, code)
        else:
            out.append((n, code))
    return "<" + "".join(f"{n if n > 1 else ''}{c}" for n, c in out)


def _values(p: Any, fields: list[dict[str, Any]]) -> list[Any]:
    out: list[Any] = []
    for f in fields:
        v = getattr(p, f["name"])
        out.extend(v if int(f.get("count", 1)) > 1 else [int(v) if isinstance(v, (bool, int)) else v])
    return out


def mismatches(layout: dict[str, Any]) -> list[str]:
    """Every way `layout` disagrees with itself or with `sea_hil.protocol.payloads` (empty: it describes the code)."""
    bad: list[str] = []
    h = layout["header"]
    if (layout["magic"].encode(), layout["version"]) != (pl.MAGIC, pl.VERSION):
        bad.append("magic/version")
    if fields_format(h["fields"]) != h["format"] or not struct.calcsize(h["format"]) == h["size"] == pl.HEADER_SIZE:
        bad.append("header format/size")
    msgs = messages(layout)
    if set(msgs) != {t.name for t in pl.MsgType}:
        bad.append(f"message types {sorted(msgs)} != {sorted(t.name for t in pl.MsgType)}")
    if layout["enums"]["reason"] != {r.name: int(r) for r in pl.TriggerReason}:
        bad.append("reason values")
    for name, m in msgs.items():
        if fields_format(m["fields"]) != m["format"]:
            bad.append(f"{name}: format {m['format']} != its fields {fields_format(m['fields'])}")
        if h["size"] + struct.calcsize(m["format"]) != m["size"] or pl.PAYLOAD_SIZE.get(pl.MsgType[name]) != m["size"]:
            bad.append(f"{name}: size")
        if name not in SAMPLES or pl.MsgType[name] != m["type_id"]:
            bad.append(f"{name}: type id")
            continue
        p = SAMPLES[name]
        data = pl.encode(p)
        try:
            head = struct.unpack_from(h["format"], data)
            body = struct.unpack_from(m["format"], data, h["size"])
        except struct.error as err:
            bad.append(f"{name}: {err}")
            continue
        if list(head) != [pl.MAGIC, pl.VERSION, m["type_id"], p.seq, p.t_ns, p.epoch] or len(data) != m["size"]:
            bad.append(f"{name}: header bytes")
        if list(body) != _values(p, m["fields"]):
            bad.append(f"{name}: fields {[f['name'] for f in m['fields']]} do not unpack to the payload's values")
        elif pl.decode(struct.pack(h["format"], *head) + struct.pack(m["format"], *body)) != p:
            bad.append(f"{name}: bytes packed from the layout do not decode to the payload")
    return bad


def test_layout_describes_the_code() -> None:
    assert mismatches(load_layout()) == []


@pytest.mark.parametrize("edit", [
    lambda lay: messages(lay)["STATE"]["fields"].reverse(),                                  # field order
    lambda lay: messages(lay)["SETPOINT"]["fields"][0].update(type="u64"),                  # field type
    lambda lay: messages(lay)["ACK"].update(size=26),                                         # size
    lambda lay: messages(lay)["VOLTAGE"].update(type_id=5),                                   # type id
    lambda lay: lay["enums"]["reason"].update(HEARTBEAT=7),                                   # enum value
    lambda lay: messages(lay)["STATE"]["fields"][1].update(name="omega_rad_s"),               # field name
])
def test_a_wrong_layout_is_caught(edit) -> None:
    layout = copy.deepcopy(load_layout())
    edit(layout)
    assert mismatches(layout)


def test_docs_tables_are_generated_from_the_layout() -> None:
    doc = DOC.read_text(encoding="utf-8")
    assert splice(doc, render_tables(load_layout())) == doc, "run python -m sea_hil.protocol.payload_layout --write"
    assert main([str(DOC), "--check"]) == 0


def test_check_reports_stale_docs(tmp_path: Path) -> None:
    stale = tmp_path / "doc.md"
    stale.write_text(DOC.read_text(encoding="utf-8").replace("| 32 | f64[2] | `theta_rad`", "| 32 | f32[2] | `theta_rad`"),
                     encoding="utf-8")
    assert main([str(stale), "--check"]) == 1
    assert main([str(stale), "--write"]) == 0 and main([str(stale), "--check"]) == 0
