"""The machine-readable payload layout (`protocol/payloads.toml`): loading it, deriving struct formats from its field
lists, and rendering docs/zenoh-protocol.md's payload tables from it, and its key table (payload types, sizes, wire
bytes and congestion control per key) from protocol/keys.py and payloads.py (issue 29: the hand-written sizes were
stale).

    python -m sea_hil.protocol.payload_layout --write docs/zenoh-protocol.md   # regenerate the tables in place
    python -m sea_hil.protocol.payload_layout --check docs/zenoh-protocol.md   # exit 1 if they are out of date

The tables sit between the `BEGIN`/`END` marker comments (payload-layout, key-table). tests/test_payload_layout.py
checks the file against `sea_hil.protocol.payloads` and the docs against the file (tests/test_key_table.py: the
key table).
"""
from __future__ import annotations

import argparse
import struct
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sea_hil.errors import ConfigError
from sea_hil.protocol.keys import CHANNELS, KEY_CONGESTION, KEY_DIRECTION, KEY_PAYLOADS, KEY_RATES
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType
from sea_hil.protocol.wire_size import TCP_BATCH_PREFIX, ZENOH_MSG_OVERHEAD, estimate_wire_bytes

LAYOUT_PATH = Path(__file__).with_name("payloads.toml")
STRUCT_CODE = {"u8": "B", "u32": "I", "u64": "Q", "f64": "d", "bytes2": "2s"}
BEGIN = "<!-- BEGIN payload-layout (generated from protocol/payloads.toml; do not edit by hand) -->"
END = "<!-- END payload-layout -->"
KEY_BEGIN = "<!-- BEGIN key-table (generated from protocol/keys.py and payloads.py; do not edit by hand) -->"
KEY_END = "<!-- END key-table -->"


def load_layout(path: Path = LAYOUT_PATH) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ConfigError(f"cannot read payload layout {path}: {err}") from err


def messages(layout: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Message name -> its table (type_id, key, format, size, fields)."""
    return {m["name"]: m for m in layout["message"]}


def _type_cell(f: dict[str, Any]) -> str:
    n = int(f.get("count", 1))
    return f"{f['type']}[{n}]" if n > 1 else f["type"]


def render_tables(layout: dict[str, Any]) -> str:
    """The markdown block between the markers: header table, one table per message, the reason values."""
    h = layout["header"]
    lines = [BEGIN, "", f"Common header, {h['size']} bytes (`{h['format']}`):", "",
             "| offset | type | field | meaning |", "|---|---|---|---|"]
    off = 0
    for f in h["fields"]:
        lines.append(f"| {off} | {_type_cell(f)} | `{f['name']}` | {f['meaning']} |")
        off += struct.calcsize("<" + STRUCT_CODE[f["type"]]) * int(f.get("count", 1))
    types = ", ".join(f"{m['type_id']} = {m['name']}" for m in layout["message"])
    lines += ["", f"Message types: {types}.", ""]
    for m in layout["message"]:
        lines += [f"**{m['name']}** (type {m['type_id']}, key `{m['key']}`, {m['direction']}): body `{m['format']}`, "
                  f"{m['size']} bytes in total.", "", "| offset | type | field | meaning |", "|---|---|---|---|"]
        off = h["size"]
        for f in m["fields"]:
            lines.append(f"| {off} | {_type_cell(f)} | `{f['name']}` | {f['meaning']} |")
            off += struct.calcsize("<" + STRUCT_CODE[f["type"]]) * int(f.get("count", 1))
        lines.append("")
    reasons = ", ".join(f"{k} = {v}" for k, v in layout["enums"]["reason"].items())
    lines += [f"SETPOINT `reason` values: {reasons}.", "", END]
    return "\n".join(lines)


def render_key_table() -> str:
    """The key table between the key-table markers, from the code: payload types (`KEY_PAYLOADS`), sizes
    (`PAYLOAD_SIZE`), the wire-size estimate (`estimate_wire_bytes`) and congestion control (`KEY_CONGESTION`)."""
    lines = [KEY_BEGIN, "", "| channel | direction | rate (defaults) | payload | payload bytes | TCP stream bytes | "
             "IPv4 bytes | Ethernet bytes | congestion control (real time / lockstep) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for ch in CHANNELS:
        types = sorted(KEY_PAYLOADS.get(ch, ()), key=int)
        payload = " / ".join(t.name for t in types) or "JSON object"
        def size(f: Callable[[int], int], types: list[MsgType] = types) -> str:
            return " / ".join(str(f(PAYLOAD_SIZE[t])) for t in types) or "variable"
        rt, ls = KEY_CONGESTION[ch]
        lines.append(f"| `{ch}` | {KEY_DIRECTION[ch]} | {KEY_RATES[ch]} | {payload} | {size(lambda n: n)} | "
                     f"{size(lambda n: n + ZENOH_MSG_OVERHEAD + (n >= 128) + TCP_BATCH_PREFIX)} | "
                     f"{size(lambda n: estimate_wire_bytes(n, ethernet=False))} | {size(estimate_wire_bytes)} | "
                     f"{rt} / {ls} |")
    return "\n".join([*lines, "", KEY_END])


def splice(doc: str, block: str, begin: str = BEGIN, end_marker: str = END) -> str:
    """`doc` with the text between the markers (inclusive) replaced by `block`."""
    start, end = doc.find(begin), doc.find(end_marker)
    if start < 0 or end < start:
        raise ConfigError(f"markers {begin!r} not found (or out of order) in the document")
    return doc[:start] + block + doc[end + len(end_marker):]


def generated(doc: str) -> str:
    """`doc` with every generated block it has marked rewritten: the payload layout, the key table."""
    if BEGIN in doc:
        doc = splice(doc, render_tables(load_layout()))
    if KEY_BEGIN in doc:
        doc = splice(doc, render_key_table(), KEY_BEGIN, KEY_END)
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sea_hil.protocol.payload_layout", description=__doc__.split("\n")[0])
    ap.add_argument("doc", type=Path, help="markdown file holding the marker comments")
    ap.add_argument("--write", action="store_true", help="rewrite the tables in place (default: check only)")
    ap.add_argument("--check", action="store_true", help="exit 1 if the tables are out of date")
    args = ap.parse_args(argv)
    doc = args.doc.read_text(encoding="utf-8")
    new = generated(doc)
    if args.write:
        args.doc.write_text(new, encoding="utf-8")
        return 0
    if new != doc:
        print(f"{args.doc}: generated tables differ from the code (run with --write)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
