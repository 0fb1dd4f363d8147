"""docs/zenoh-protocol.md's key table is the code's (issue 29: it gave 88 / 53 / 36 / 25 B while the wire carries 96
/ 61 / 44 / 33): generated from protocol/keys.py and payloads.py, and the congestion control it states per key is
the one the built-in nodes' publishers use, in real time and in lockstep. No hand-written payload size elsewhere in
the docs disagrees with `PAYLOAD_SIZE`."""
from __future__ import annotations

import re
import uuid
from pathlib import Path

import pytest
import zenoh
from paper_scheme import paper

from sea_hil.config.loader import load_config
from sea_hil.protocol.keys import KEY_CONGESTION
from sea_hil.protocol.payload_layout import KEY_BEGIN, KEY_END, main, render_key_table
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType
from sea_hil.session.builder import SessionBuilder

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "zenoh-protocol.md"


def test_the_docs_key_table_is_the_generated_one() -> None:
    doc = DOC.read_text(encoding="utf-8")
    block = render_key_table()
    assert doc[doc.index(KEY_BEGIN):doc.index(KEY_END) + len(KEY_END)] == block
    assert main([str(DOC), "--check"]) == 0
    for t, n in ((MsgType.STATE, 96), (MsgType.SETPOINT, 61), (MsgType.VOLTAGE, 44), (MsgType.ACK, 33)):
        assert PAYLOAD_SIZE[t] == n and f"| {n}" in block     # the sizes measured on the wire (issue 29)


@pytest.mark.parametrize("lockstep", [False, True])
def test_the_stated_congestion_control_is_the_nodes(lockstep: bool) -> None:
    with SessionBuilder(load_config(overrides=paper()), lockstep=lockstep) as b:
        session = b.zenoh()
        edge = b.edge(b.bus(f"virtual:cc-{uuid.uuid4().hex[:8]}"), session, 1)
        ctrl = b.controller(session, "et")
        pubs = {"state": edge.state_pub, "setpoint": ctrl.sp_pub, "voltage": ctrl.v_pub,
                "event": ctrl.event_pub, "stats": edge.stats_pub}
        if lockstep:
            pubs["control"] = ctrl.sync.ack_pub
        for ch, pub in pubs.items():
            want = KEY_CONGESTION[ch][1 if lockstep else 0]
            assert pub.congestion_control == getattr(zenoh.CongestionControl, want), ch


def test_no_doc_repeats_an_old_payload_size() -> None:
    """The sizes before the epoch (payload version 1: 88 / 53 / 36 / 25 B) appear only where a doc says they are
    the old ones (deviations.md's epoch section, the pre-restructuring fixtures' note)."""
    old = re.compile(r"\b(88|53|36|25)[- ](B|bytes?|byte)\b")
    for path in sorted((REPO / "docs").glob("*.md")):
        for line in path.read_text(encoding="utf-8").splitlines():
            if old.search(line) and "version 1" not in line and "was " not in line:
                raise AssertionError(f"{path.name}: {line.strip()}")
