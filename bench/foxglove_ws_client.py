"""An independent Foxglove WebSocket client, written from the protocol spec
(https://github.com/foxglove/ws-protocol/blob/main/docs/spec.md) with the `websockets` package, no foxglove-sdk code.

Subprotocol negotiation (foxglove-sdk 0.30 answers `foxglove.sdk.v1`, older servers `foxglove.websocket.v1`),
`serverInfo`, `advertise`, `subscribe`, and binary message data: opcode 0x01, uint32 subscription id, uint64 log
time (little-endian), payload. Used by the live view's acceptance test and by bench/bench_live.py.
"""
from __future__ import annotations

import asyncio
import json
import struct
from dataclasses import dataclass, field
from typing import Any

import websockets
from websockets.typing import Subprotocol

SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


@dataclass
class Received:
    subprotocol: str | None = None
    server_info: dict[str, Any] = field(default_factory=dict)
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)         # channel id -> advertised channel
    messages: dict[str, list[tuple[int, Any]]] = field(default_factory=dict)  # topic -> [(log_time_ns, message)]
    unknown_subscription: int = 0
    ended: bool = False

    def by_topic(self) -> dict[str, dict[str, Any]]:
        return {c["topic"]: c for c in self.channels.values()}


def _is_end(msg: Any, end_message: str) -> bool:
    return isinstance(msg, dict) and msg.get("name") == "sea-hil" and msg.get("message") == end_message


async def receive(url: str, topics: set[str], *, end_message: str, timeout_s: float) -> Received:
    """Connect, wait until every topic in `topics` is advertised, subscribe to all of them in one `subscribe`
    message, then collect JSON messages until the end-of-session log line (or the server closes)."""
    out = Received()
    subs: dict[int, str] = {}
    async with asyncio.timeout(timeout_s):
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
            out.subprotocol = ws.subprotocol
            while not topics <= set(out.by_topic()):
                _control(json.loads(await ws.recv()), out)
            wanted = [c for c in out.channels.values() if c["topic"] in topics]
            subs = {i + 1: c["topic"] for i, c in enumerate(wanted)}
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": sid, "channelId": c["id"]} for sid, c in zip(subs, wanted, strict=True)]}))
            try:
                async for frame in ws:
                    if isinstance(frame, str):
                        _control(json.loads(frame), out)
                        continue
                    op, sid, log_time = _HEADER.unpack_from(frame)
                    if op != MESSAGE_DATA:
                        continue
                    if sid not in subs:
                        out.unknown_subscription += 1
                        continue
                    msg = json.loads(frame[_HEADER.size:])
                    out.messages.setdefault(subs[sid], []).append((log_time, msg))
                    if _is_end(msg, end_message):
                        out.ended = True
                        break
            except websockets.ConnectionClosed:
                pass
    return out


def _control(msg: dict[str, Any], out: Received) -> None:
    if msg.get("op") == "serverInfo":
        out.server_info = msg
    elif msg.get("op") == "advertise":
        for ch in msg["channels"]:
            out.channels[ch["id"]] = ch
    elif msg.get("op") == "unadvertise":
        for cid in msg["channelIds"]:
            out.channels.pop(cid, None)
