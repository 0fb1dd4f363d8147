"""An independent reader (npm `@mcap/core` under node, zstd through `fzstd`, JSON Schema through `ajv`) reads a
short lockstep session file: every channel's messages decode and validate against their own schemas (the protobuf
CAN channels decoded by protobufjs from the file's FileDescriptorSet, equal to what sea-hil's reader gives), log times are
monotonic per channel and in the session's sample time, the well-known schemas are Foxglove's, the chunk count in
the final metadata is the file's. The JS lives in tests/js (`npm ci` there; scripts/test does it)."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from sea_hil.config.loader import load_config
from sea_hil.recorder.binary import BINARY_TOPICS
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.schemas import TOPICS, encodings
from sea_hil.session.run import RunOptions, run_session

JS = Path(__file__).resolve().parent / "js"
NODE = shutil.which("node")
PERIOD_S = 0.5
pytestmark = [pytest.mark.skipif(NODE is None, reason="node is not installed (the independent MCAP reader is JS)"),
              pytest.mark.skipif(not (JS / "node_modules" / "@mcap" / "core").is_dir(),
                                 reason="npm packages missing: run `npm ci` in tests/js (scripts/test does)")]


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    out = tmp_path_factory.mktemp("node") / "run"
    cfg = load_config(overrides={"trajectory": {"period_s": PERIOD_S}})
    summary = run_session(cfg, RunOptions(controller="et", out=out, lockstep=True, progress=False, figures=False))
    res = subprocess.run([NODE, str(JS / "check_mcap.mjs"), str(out / "session.mcap")], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout), summary, cfg, out / "session.mcap"


@pytest.mark.parametrize("topic", TOPICS)
def test_every_message_decodes_and_validates_in_log_time_order(checked, topic):
    report = checked[0]
    ch = report["channels"][topic]
    assert (ch["schemaEncoding"], ch["messageEncoding"]) == encodings(topic)
    assert (ch["undecodable"], ch["invalid"], ch["nonMonotonic"]) == (0, 0, 0), ch["firstErrors"]
    assert ch["publishEqualsLog"] == ch["messages"]


def test_file_is_whole_and_recorded_what_the_session_sent(checked):
    report, summary, _, _ = checked
    assert report["errors"] == [] and report["indexedMessages"] == sum(c["messages"] for c in
                                                                       report["channels"].values())
    final = report["metadata"]["sea-hil.final"]
    assert int(final["chunks_written"]) == report["chunks"] == report["summaryChunks"]
    ch = report["channels"]
    assert ch["/zenoh/setpoint"]["messages"] >= summary["transmissions"]["downlink_msgs"] > 0
    assert ch["/joint_states"]["messages"] == ch["/zenoh/state"]["messages"]
    assert 0 < ch["/log/events"]["messages"] <= ch["/zenoh/setpoint"]["messages"]  # one per event (+ re-sends)
    assert ch["/log/faults"]["messages"] >= 1                                 # the driver going RUNNING
    assert report["wellKnownSchemasMatch"] == {"foxglove.Log": True, "foxglove.JointStates": True}


def test_sequence_is_the_senders(checked):
    ch = checked[0]["channels"]
    for topic in ("/zenoh/state", "/zenoh/setpoint", "/joint_states", "/tracking"):
        assert ch[topic]["messages"] and ch[topic]["seqZero"] == 0, topic   # u32 counters starting at 1
    # CAN frames carry an 8-bit seq: 0 once per 256 frames of an id, plus the frames without one (heartbeats start)
    assert ch["/can/command"]["seqZero"] <= ch["/can/command"]["messages"] / 256 + 1


def test_lockstep_log_time_is_the_sample_time(checked):
    ch, _, cfg = checked[0]["channels"], checked[1], checked[2]
    simulated_s = cfg.trajectory.lead_in_s + PERIOD_S
    for topic in ("/can/feedback", "/zenoh/state", "/tracking"):
        lo, hi = int(ch[topic]["logTimeMin"]), int(ch[topic]["logTimeMax"])
        assert lo < 0.05e9 and hi * 1e-9 == pytest.approx(simulated_s, abs=0.03), topic


def test_binary_channels_decode_independently_to_what_the_reader_gives(checked):
    report, path = checked[0], checked[3]
    data = read_session(path)
    for topic in BINARY_TOPICS:
        assert report["channels"][topic]["messageEncoding"] == "protobuf"
        js = report["channels"][topic]["decoded"]
        ours = [m.payload for m in data.messages[topic]]   # log-time order = file order (monotonic per channel)
        assert len(js) == len(ours) == report["channels"][topic]["messages"] > 100, topic
        assert js == ours, topic   # every field and value (doubles through JSON's shortest repr: exact)
