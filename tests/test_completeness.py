"""Issue 32: a recording checked against the nodes' own counters (sea_hil/report/completeness.py) and what
`report` writes for figures it cannot compute. Synthetic recordings (tests/test_session_summary.py's); the
four-process topologies are tests/test_compose_topology.py."""
from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
from test_session_summary import _session

from sea_hil.cli import main
from sea_hil.commands.report import node_counters_of
from sea_hil.errors import ConfigError
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.completeness import COMPLETENESS_SCHEMA, completeness_block
from sea_hil.report.console import end_of_run_rows
from sea_hil.report.session_summary import session_summary
from sea_hil.report.writer import report_markdown
from sea_hil.verdict.edge_blocks import uplink_losses

PUBLISHED = range(1, 176)
EVENTS = {20, 30, 100}


def _final(node: str, **counters: int) -> RecordedMessage:
    return RecordedMessage(0, 0, {"node": node, "final": True, "t_ns": 0, **counters})


def _with_finals(data: SessionData, *finals: RecordedMessage) -> SessionData:
    data.messages["/stats"] = list(finals)
    return data


def test_a_recording_with_every_message_is_complete() -> None:
    data = _with_finals(_session(20, 170, PUBLISHED, EVENTS), _final("edge", uplink_msgs=len(PUBLISHED)),
                        _final("controller", setpoints_sent=len(EVENTS)))
    block = completeness_block(data)
    jsonschema.validate(block, COMPLETENESS_SCHEMA)
    assert block["complete"] and block["incomplete"] == [] and block["unverified"] == []
    assert block["channels"]["can_command"]["status"] == "not recorded"   # no CAN tap: not a loss


def test_a_recorder_started_late_says_what_it_missed() -> None:
    data = _with_finals(_session(20, 170, range(41, 176), EVENTS),    # states 1..40 published before it joined
                        _final("edge", uplink_msgs=len(PUBLISHED)), _final("controller", setpoints_sent=5))
    block = completeness_block(data)
    assert block["incomplete"] == ["state", "downlink"] and not block["complete"]
    assert block["channels"]["state"] | {"source": ""} == {"status": "incomplete", "expected": 175, "recorded": 135,
                                                           "missing": 40, "source": ""}
    assert block["channels"]["downlink"]["missing"] == 2
    md = report_markdown({**session_summary(data, "et"), "completeness": block}, data)
    assert "incomplete: 40 of 175 messages not recorded" in md and "recording complete | no: state: 40 of 175" in md


def test_a_recorder_cut_off_mid_session_cannot_verify_and_writes_not_recorded() -> None:
    data = _session(20, 170, range(1, 60), set())        # cut off: no setpoint yet, no node's final record
    block = completeness_block(data)
    assert block["unverified"] == ["state", "downlink"] and block["never_seen"] == ["edge final stats",
                                                                                   "controller final stats"]
    summary = {**session_summary(data, "et"), "completeness": block}
    assert summary["timing"]["latency_us"]["p50"] == -1.0       # summary.json keeps numbers (its schema) ...
    md = report_markdown(summary, data)
    assert "| closed-loop latency p50 / p99 / max [us] | not recorded |" in md    # ... report.md says so
    assert "| downlink messages / bytes | not recorded |" in md and "-1" not in md


def test_can_frames_lost_on_the_bus_are_counted_against_the_recording() -> None:
    data = _with_finals(_session(20, 170, PUBLISHED, EVENTS), _final("edge", uplink_msgs=len(PUBLISHED)),
                        _final("controller", setpoints_sent=len(EVENTS)))
    data.metadata["sea-hil.final"] = {"can_frames": "1000", "can_frames_missed": "7", "dropped": "0"}
    block = completeness_block(data)
    assert block["can_frames_lost"] == 7 and "can_frames" in block["incomplete"]
    assert block["channels"]["can_frames"]["missing"] == 7 and block["channels"]["can_frames"]["expected"] == 1007


def test_a_cut_off_recording_checked_against_the_nodes_own_summaries() -> None:
    """The edge's and controller's final records never reached the recorder; their `--json` results from their
    hosts (`sea-hil report --node-summary`) say how much it missed."""
    data = _session(20, 170, range(1, 60), {20, 30})
    block = completeness_block(data, {"edge": {"uplink_msgs": 175, "uplink_pending": 0},
                                      "controller": {"setpoints_sent": 3}})
    jsonschema.validate(block, COMPLETENESS_SCHEMA)
    assert block["incomplete"] == ["state", "downlink"] and block["unverified"] == []
    assert (block["channels"]["state"]["missing"], block["channels"]["downlink"]["missing"]) == (175 - 59, 1)
    assert block["counters_from_node_summaries"] == ["controller", "edge"] and not block["complete"]


# ---- several limbs: each limb's channels against its own nodes' counters ------------------------------------------
LIMBS_META = {"limb1": "1 virtual:sea-hil0", "limb2": "2 virtual:sea-hil1"}


def _as_limb(data: SessionData, limb: str) -> dict[str, list[RecordedMessage]]:
    """`data`'s messages (limb1's keys) as those of `limb`."""
    def moved(m: RecordedMessage) -> RecordedMessage:
        key = m.payload.get("key")
        return m if not isinstance(key, str) else RecordedMessage(m.log_time_ns, m.publish_time_ns, {
            **m.payload, "key": key.replace("/limb1/", f"/{limb}/")}, m.sequence)
    return {topic: [moved(m) for m in msgs] for topic, msgs in data.messages.items()}


def two_limbs(published2: range = PUBLISHED, edge2: dict[str, int] | None = None,
              edge1: dict[str, int] | None = None, controller_node_ids: bool = True,
              controller2: dict[str, int] | None = None) -> SessionData:
    """A recording of two limbs (node ids 1 and 2), each with its edge's and controller's final record (the
    controller's with its limb's `node_id`, as `sea-hil controller` writes it, or without: an outside controller;
    limb2's with `controller2` counters); limb2's recorder kept `published2` of its states."""
    one, two = _session(20, 170, PUBLISHED, EVENTS), _as_limb(_session(20, 170, published2, EVENTS), "limb2")
    data = SessionData(messages={t: one.messages.get(t, []) + two.get(t, []) for t in {*one.messages, *two}},
                       metadata={"sea-hil.limbs": dict(LIMBS_META)})
    data.messages["/stats"] = [
        *(_final("edge", **{"node_id": n, "uplink_msgs": len(PUBLISHED), **(extra or {})})
          for n, extra in ((1, edge1), (2, edge2))),
        *(_final("controller", setpoints_sent=len(EVENTS), **({"node_id": n} if controller_node_ids else {}),
                 **{"state_seq_lost": 0, **(controller2 or {} if n == 2 else {})})
          for n in (1, 2))]
    return data


def test_two_complete_limbs_are_complete() -> None:
    for by_node in (True, False):
        block = completeness_block(two_limbs(controller_node_ids=by_node))
        jsonschema.validate(block, COMPLETENESS_SCHEMA)
        assert block["complete"] and block["incomplete"] == [], block
        assert ("downlink.limb2" in block["channels"]) is by_node and ("downlink" in block["channels"]) is not by_node


def test_one_limbs_surplus_does_not_hide_anothers_shortfall() -> None:
    """limb2's recorder missed its first 40 states; limb1's file holds 40 states more than its edge counted (an
    edge restarted mid-session: the records of its first run). Summed over the limbs the state channel balances;
    per limb it does not."""
    data = two_limbs(published2=range(41, 176), edge1={"uplink_msgs": len(PUBLISHED) - 40})
    block = completeness_block(data)
    assert not block["complete"] and block["incomplete"] == ["state.limb2"], block
    c = block["channels"]["state.limb2"]
    assert (c["expected"], c["recorded"], c["missing"]) == (175, 135, 40)
    assert block["channels"]["state.limb1"]["extra"] == 40
    reasons = session_summary(data, "et")["verdict"]["reasons"]
    assert [(r["code"], r.get("channel")) for r in reasons] == [("recording_incomplete", "state.limb2")], reasons


def test_a_limb_without_its_nodes_final_records_is_unverified() -> None:
    data = two_limbs()
    data.messages["/stats"] = [m for m in data.messages["/stats"] if m.payload.get("node_id") != 2]
    block = completeness_block(data)
    assert sorted(block["unverified"]) == ["downlink.limb2", "state.limb2"], block
    assert block["never_seen"] == ["edge final stats (limb2)", "controller final stats (limb2)"]
    supplied = completeness_block(data, [("edge", {"node_id": 2, "uplink_msgs": len(PUBLISHED)})])
    assert supplied["unverified"] == ["downlink.limb2"] and supplied["counters_from_node_summaries"] == [
        "edge (limb2)"]


def _node_file(tmp: Path, name: str, kind: str, **counters: int) -> Path:
    path = tmp / name
    path.write_text("a table line first\n" + json.dumps({"node": kind, "finished": True, "counters": counters}) + "\n",
                    encoding="utf-8")
    return path


def test_two_node_summaries_of_one_node_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`report --node-summary A --node-summary B` with two summaries of the same node: exit 2, one line naming both
    (the second silently replaced the first); two limbs' edges (different node_id) are both used."""
    rec = tmp_path / "run.mcap"
    rec.write_bytes(b"")       # never read: the summaries are checked first
    a = _node_file(tmp_path, "a.json", "edge", node_id=1, uplink_msgs=10)
    b = _node_file(tmp_path, "b.json", "edge", node_id=1, uplink_msgs=12)
    assert main(["report", str(rec), "--out", str(tmp_path / "o"), "--node-summary", str(a), "--node-summary",
                 str(b)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a second edge summary of node 1" in err[0] and "a.json" in err[0], err
    c1 = _node_file(tmp_path, "c1.json", "controller", setpoints_sent=3)     # an outside controller: no node_id
    c2 = _node_file(tmp_path, "c2.json", "controller", node_id=2, setpoints_sent=3)
    with pytest.raises(ConfigError, match="a second controller summary"):
        node_counters_of([c1, c2])
    two = _node_file(tmp_path, "two.json", "edge", node_id=2, uplink_msgs=len(PUBLISHED))
    assert node_counters_of([a, two]) == [("edge", {"node_id": 1, "uplink_msgs": 10}),
                                          ("edge", {"node_id": 2, "uplink_msgs": len(PUBLISHED)})]
    data = two_limbs()
    data.messages["/stats"] = [m for m in data.messages["/stats"] if m.payload.get("node") != "edge"]
    block = completeness_block(data, node_counters_of([_node_file(tmp_path, "e1.json", "edge", node_id=1,
                                                                  uplink_msgs=len(PUBLISHED)), two]))
    assert block["counters_from_node_summaries"] == ["edge (limb1)", "edge (limb2)"] and block["unverified"] == []


def test_a_recorder_cut_off_in_the_lead_in_writes_not_recorded_for_the_cycle() -> None:
    """Cut off before the measured cycle (issue 32, seen with a recorder SIGKILLed 10 states into a real session):
    the file holds only lead-in tracking records (t < 0), so the cycle's tracking and inter-event figures are not
    measurements; report.md and the end-of-run table say "not recorded" instead of 0.0000."""
    data = _session(20, 60, range(1, 61), {30})          # the lead-in is seqs 20..69: no record at t >= 0
    summary = {**session_summary(data, "et"), "completeness": completeness_block(data)}
    assert summary["duration_s"] == 0.0 and summary["lead_in"]["uplink_msgs"] > 0
    md = report_markdown(summary, data)
    for figure in ("max abs tracking error hip / knee [rad]", "rms tracking error hip / knee [rad]",
                   "inter-event min / median / max [s]"):
        assert f"| {figure} | not recorded |" in md, md
    rows = dict(end_of_run_rows(summary, command="report"))
    assert rows["error hip max / RMS"] == rows["error knee max / RMS"] == "not recorded", rows
    # a cycle in the file: its figures are shown
    whole = _session(20, 170, PUBLISHED, EVENTS)
    rows = dict(end_of_run_rows({**session_summary(whole, "et"), "completeness": completeness_block(whole)}))
    assert rows["error hip max / RMS"].endswith(" rad"), rows
    assert "| max abs tracking error hip / knee [rad] | not recorded |" not in report_markdown(
        session_summary(whole, "et"), whole)


def test_a_standalone_recording_is_judged_as_the_edge_ran() -> None:
    """`sea-hil record` of a distributed session writes no `lockstep` in its session metadata: the kind of run is the
    edge's own (its final /stats `lockstep`), so a real-time session's stale setpoints (a real-time-only rule) are
    judged and a lockstep one's re-sent answers are not; `sea-hil run`'s metadata, when there, decides."""
    def judged(lockstep: int, meta: dict[str, str] | None = None) -> list[str]:
        data = _with_finals(_session(20, 170, PUBLISHED, EVENTS),
                            _final("edge", uplink_msgs=len(PUBLISHED), stale_setpoints=50, lockstep=lockstep),
                            _final("controller", setpoints_sent=len(EVENTS)))
        if meta is not None:
            data.metadata["sea-hil.session"] = meta
        return [r["code"] for r in session_summary(data, "et")["verdict"]["reasons"]]
    assert "stale_setpoints" in judged(0)
    assert "stale_setpoints" not in judged(1)
    assert "stale_setpoints" not in judged(0, {"lockstep": "True"})   # `run`'s own word
    assert "stale_setpoints" in judged(1, {"lockstep": "False"})


def test_states_a_newer_one_replaced_are_no_loss_on_the_way() -> None:
    """In real time the controller reads the newest state only: the ones a newer state replaced before it read them
    arrived (`states_superseded`); only the rest of its stream-seq gaps, beyond the uplink model's own drops, are
    states lost on the way (`link_losses.uplink_beyond_model`, the `lost_states` rule)."""
    assert uplink_losses({"state_seq_lost": 20, "states_superseded": 5}, {"uplink_dropped": 3}) == {
        "uplink_beyond_model": 12}
    assert uplink_losses({"state_seq_lost": 4, "states_superseded": 4}, {}) == {"uplink_beyond_model": 0}
    assert uplink_losses({"state_seq_lost": 7}, {"uplink_dropped": 2}) == {"uplink_beyond_model": 5}   # lockstep
