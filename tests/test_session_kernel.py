"""The whole-session kernel (sea_hil/offline/session_kernel.py) against the Python sample loop it replaces for the
paper's scheme: every recorded message, bit for bit, and every count, over the link, trigger, lead-in, disturbance,
envelope and fault cases the kernel handles itself. Short trajectories: each case costs well under a second."""
from __future__ import annotations

import logging

import pytest
from paper_scheme import paper

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import driver_disturbance_table, run_engine
from sea_hil.offline.session_fast import delivery_offsets, unsupported
from sea_hil.offline.session_loop import EngineOptions
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.protocol.link import LinkEmulator, parse_link_spec

SHORT = {"trajectory": {"period_s": 1.5, "lead_in_s": 0.3}}
CASES = {
    "ideal": ({}, None),
    "jitter-loss": ({}, "delay=5ms,jitter=2ms,dist=normal,loss=2%"),
    "reorder-bursts": ({}, "delay=3ms,jitter=4ms,dist=uniform,loss=1%,ge=0.05/0.3/0.8,reorder=on"),
    "exponential-long": ({"trigger": {"eta": 0.3, "r": 0.05}}, "delay=20ms,jitter=5ms,dist=exponential,loss=5%"),
    "no-lead-in": ({"trajectory": {"period_s": 1.5, "lead_in_s": 0.0}}, "delay=1ms"),
    "noise-paper-inner": ({"disturbance": {"kind": "noise", "amplitude_nm": [0.3, 0.05], "seed": 3},
                           "controller": {"disturbance_compensation": "off"}}, "delay=2ms,jitter=1ms"),
    "knee-sine": ({"disturbance": {"knee": {"kind": "sine", "amplitude_nm": 0.05, "frequency_hz": 2.0}}}, None),
    "envelope": ({"safety": {"setpoint": {"deflection_max_m": [0.0012, 0.0012]}}}, "delay=10ms,jitter=2ms"),
    "drive-fault": ({"safety": {"drive": {"velocity_max_rad_s": [0.4, 0.4]}}}, None),
    "late-answers": ({"safety": {"setpoint": {"max_answer_age_s": 0.03}}}, "delay=12ms,jitter=6ms,dist=normal"),
}


def _cfg(case: str):
    extra, link = CASES[case]
    ov = {**SHORT, "link": {"seed": 4}, **extra}
    if link:
        ov["link"] = {"seed": 4, "uplink": parse_link_spec(link), "downlink": parse_link_spec(link)}
    return load_config(None, paper(ov))     # the kernel covers the paper's scheme only


@pytest.mark.parametrize("mode", ["et", "tt"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_whole_session_kernel_equals_the_sample_loop(case, mode, caplog):
    cfg = _cfg(case)
    with caplog.at_level(logging.WARNING, logger="sea_hil.offline"):
        loop = run_engine(cfg, mode, whole=False)
        loop_log = [r.getMessage() for r in caplog.records]
        caplog.clear()
        whole = run_engine(cfg, mode)
        whole_log = [r.getMessage() for r in caplog.records]
    assert whole.data.messages == loop.data.messages
    assert (whole.samples, whole.saturated_steps, whole.drive_faulted, whole.setpoints_out_of_envelope) == \
        (loop.samples, loop.saturated_steps, loop.drive_faulted, loop.setpoints_out_of_envelope)
    assert whole_log == loop_log        # the envelope's rejections, logged in the same order
    if case == "envelope":
        assert whole.setpoints_out_of_envelope > 0
    if case == "drive-fault":
        assert whole.drive_faulted
    if case == "late-answers":      # answers to states older than 30 ms were dropped: another session than without
        off = load_config(None, paper({**SHORT, "link": cfg.link.model_dump(),
                                       "safety": {"setpoint": {"max_answer_age_s": 0.0}}}))
        assert run_engine(off, mode).data.messages != whole.data.messages


def test_delivery_offsets_are_the_emulators_own():
    spec = parse_link_spec("delay=5ms,jitter=3ms,dist=normal,loss=10%,ge=0.1/0.3/0.9")
    cfg = load_config(None, {"link": {"uplink": spec}}).link.uplink
    live = LinkEmulator(cfg.model_copy(update={"reorder": True}), "7/up")
    offsets = delivery_offsets(cfg, "7/up", 500, 77).tolist()
    sent = [1_000_000 * i for i in range(500)]
    got = [live.submit(t, 77) for t in sent]
    assert offsets == [-1 if a is None else a - t for a, t in zip(got, sent, strict=True)]
    assert -1 in offsets and min(a for a in offsets if a >= 0) >= 0


def test_unsupported_options_run_the_sample_loop():
    cfg = _cfg("ideal")
    traj = type("Csv", (), {})()
    assert unsupported(cfg, EngineOptions(), traj) == "a CSV trajectory"
    assert "placement 'edge'" in unsupported(cfg, EngineOptions(placement="edge"), None)
    rate = load_config(None, {"link": {"downlink": parse_link_spec("rate=1Mbps")}})
    from sea_hil.controller.trajectory import GaitTrajectory
    assert unsupported(rate, EngineOptions(), GaitTrajectory(1.0)) == "a downlink trace or rate limit"
    assert unsupported(cfg, EngineOptions(), GaitTrajectory(1.0)) == ""


def test_per_joint_disturbance_reaches_the_offline_driver():
    cfg = _cfg("knee-sine")
    tab = driver_disturbance_table(cfg, 50, 1_000_000)
    dist = make_disturbance(cfg.disturbance)
    h = 1e-3 / cfg.sim.substeps
    assert tab[:, 1].any() and not tab[:, 0].any()
    k, i = divmod(7, cfg.sim.substeps)
    t = k * 1_000_000 * 1e-9 + i * h
    assert tuple(tab[7]) == (*dist(t), *dist(t + 0.5 * h), *dist(t + h))
