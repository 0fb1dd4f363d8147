"""A sweep point's summary straight from the whole-session kernel's records (sea_hil/offline/kernel_summary.py) is
`session_summary` of the session's messages: the same dict (==, floats bit for bit), over the link, trigger, lead-in,
disturbance, envelope and fault cases of tests/test_session_kernel.py and two full-length points of the benchmark
grid; a session the kernel does not cover takes the message path."""
from __future__ import annotations

import pytest
from test_session_kernel import CASES, _cfg

from sea_hil.config.loader import load_config
from sea_hil.offline import session_engine
from sea_hil.offline.session_engine import engine_summary, engine_verdict, run_engine
from sea_hil.protocol.link import parse_link_spec
from sea_hil.report.session_summary import session_summary


@pytest.mark.parametrize("mode", ["et", "tt"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_kernel_summary_equals_the_message_summary(case, mode):
    cfg = _cfg(case)
    res = run_engine(cfg, mode)   # the verdict: the engine's fault flag and saturated steps, either path
    assert engine_summary(cfg, mode) == engine_verdict(session_summary(res.data, mode), res.drive_faulted,
                                                       res.saturated_steps, res.samples, cfg)


@pytest.mark.parametrize("spec", ["delay=20ms,jitter=5ms,loss=5%", "delay=5ms,jitter=1ms,loss=1%"])
def test_full_length_grid_point(spec):
    link = parse_link_spec(spec)
    cfg = load_config(None, {"link": {"seed": 1, "uplink": link, "downlink": link},
                             "trigger": {"eta": 0.2, "r": 0.05}, "disturbance": {"seed": 1}})
    fast = engine_summary(cfg, "et")
    res = run_engine(cfg, "et")
    assert fast == engine_verdict(session_summary(res.data, "et"), res.drive_faulted, res.saturated_steps,
                                  res.samples, cfg)
    assert fast["lead_in"]["downlink_msgs"] > 0 and fast["uplink_outside_msgs"] >= 0


def test_uncovered_session_takes_the_message_path(monkeypatch):
    calls = []
    monkeypatch.setattr(session_engine, "run_kernel", lambda *a: calls.append(a))
    cfg = load_config(None, {"trajectory": {"period_s": 1.5, "lead_in_s": 0.3},
                             "controller": {"compensation": "predict"}})
    res = run_engine(cfg, "et")
    assert engine_summary(cfg, "et") == engine_verdict(session_summary(res.data, "et"), res.drive_faulted,
                                                       res.saturated_steps, res.samples, cfg)
    assert calls == []
