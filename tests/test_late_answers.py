"""Late answers (issue 19, `[safety.setpoint] max_answer_age_s`): the edge applies a setpoint only if the state it
answers was sampled at most that long before; a later one is counted, logged and dropped (the setpoint timeout and
the local fallback act as if it had been lost), and the local fallback's answer timeout is capped at that age. The
offline engine does the same (tests/test_engine_lockstep.py, case late-answers)."""
from __future__ import annotations

import logging

import pytest

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.config.loader import load_config
from sea_hil.controller.edge_core import EdgeCounters, SetpointIntake
from sea_hil.controller.edge_trigger import EdgeEventGenerator
from sea_hil.controller.trajectory import make_trajectory
from sea_hil.controller.trigger import EventTrigger
from sea_hil.protocol.link import LinkEmulator
from sea_hil.protocol.payloads import PayloadCounters, SetpointPayload, TriggerReason, encode

MS = 1_000_000


def _intake(max_age_ns: int) -> SetpointIntake:
    return SetpointIntake(LinkEmulator(LinkDirectionConfig(), "1/down"), EdgeCounters(), PayloadCounters(),
                          500 * MS, lambda timed_out: timed_out, None, max_age_ns)


def _setpoint(seq: int, state_seq: int) -> bytes:
    return encode(SetpointPayload(seq, 0, state_seq, (1e-4, 0.0), (0.0, 0.0), TriggerReason.ERROR_BOUND, epoch=7))


@pytest.mark.parametrize("age_ms, applied", [(199, True), (200, True), (201, False)])
def test_a_setpoint_for_a_state_older_than_the_limit_is_dropped_and_counted(age_ms, applied, caplog):
    intake, got = _intake(200 * MS), []
    sampled_at = {5: 1_000 * MS}
    now = sampled_at[5] + age_ms * MS
    assert intake.submit(_setpoint(1, 5), now, {}, None)
    with caplog.at_level(logging.WARNING, "sea_hil.edge"):
        assert intake.take(now, {}, sampled_at, got.append) is applied
    assert len(got) == int(applied) and intake.counters.late_setpoints == int(not applied)
    assert intake.fresh(now) is applied          # a dropped answer does not refresh the setpoint timeout
    assert ("late setpoint 1 dropped" in caplog.text) is not applied


def test_the_limit_off_applies_any_age():
    intake, got = _intake(0), []
    assert intake.submit(_setpoint(1, 5), 10_000 * MS, {}, None)
    assert intake.take(10_000 * MS, {}, {5: 0}, got.append) and intake.counters.late_setpoints == 0


def test_the_answer_timeout_follows_the_round_trip_up_to_the_cap():
    traj = make_trajectory(load_config().trajectory)
    gens = [EdgeEventGenerator(EventTrigger(1e9, 0.01, 250 * MS), traj, 0, lookahead=False, max_timeout_ns=cap)
            for cap in (0, 200 * MS)]
    for gen in gens:
        gen.answered(1, 150 * MS, 0)              # a 150 ms round trip
    assert [g.answer_timeout_ns for g in gens] == [450 * MS, 200 * MS]
    for gen in gens:
        gen.rtt_ns = 10 * MS                      # a short round trip: the cap does not act
    assert [g.answer_timeout_ns for g in gens] == [30 * MS, 30 * MS]


def test_the_default_is_above_the_modelled_links():
    """The default leaves every link of the tools' tables alone (20 ms + 5 ms jitter each way); the lockstep
    fixtures and the issue-16 rows are unchanged with it (tests/test_pre_refactor_equality.py)."""
    assert load_config().safety.setpoint.max_answer_age_s == pytest.approx(0.2)
