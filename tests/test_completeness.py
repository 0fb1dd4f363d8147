"""Issue 32: a recording checked against the nodes' own counters (sea_hil/report/completeness.py) and what
`report` writes for figures it cannot compute. Synthetic recordings (tests/test_session_summary.py's); the
four-process topologies are tests/test_compose_topology.py."""
from __future__ import annotations

import jsonschema
from test_session_summary import _session

from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.completeness import COMPLETENESS_SCHEMA, completeness_block
from sea_hil.report.console import end_of_run_rows
from sea_hil.report.session_summary import session_summary
from sea_hil.report.writer import report_markdown

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
