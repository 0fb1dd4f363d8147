"""Offline engine of a networked session: the lockstep session's timeline in one process, with the same link
emulation, the same wire quantisation and the same summary, fast enough for sweeps of thousands of points.

What it replays, sample by sample (1 ms), as `sea-hil run --lockstep` orders it (docs/sweep.md, "Offline engine"):
the driver boots at rest (`plant.initial_theta_rad`) and integrates each period exactly as `DriverCore.step` does
(the same float expressions and sub-steps, disturbance sampled at the same times); the edge publishes a state every
outer sample through the uplink `LinkEmulator` (same seed stream `<seed>/up`, same payload size), the controller
answers each released state at once (lead-in, trigger, SMC: the live `OuterController` and `LeadIn`), a setpoint
enters the downlink emulator (`<seed>/down`) at that sample and is applied when released; the edge's voltage is the
backstepping law on the DBC-quantised feedback, quantised and saturated as the VOLTAGE_CMD frame does. Two
implementations of that loop, with the same results: the whole session in one numba call for the paper's scheme
(`sea_hil.offline.session_fast`, `session_kernel`: the outer loop compiled from the live controller's plain-float
functions), and the Python sample loop for every option (`sea_hil.offline.session_loop`; per-sample part in a numba
kernel, `drive_kernel`, outer part in Python). The messages a recorder would see (states as delivered, setpoints as published, tracking records) are built as
the recorder's `zenoh_record` builds them and summarised by `session_summary`, so the summary is the session's.

Not replayed: wall-clock quantities (latency, loop times), the edge's `/stats`, and `max_abs_voltage_v` is taken up to
the controller's last sample (a session also records the commands of its shut-down tail).
"""
from __future__ import annotations

import logging
from typing import Any

from sea_hil.config import SeaHilConfig
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.trajectory import lead_in_duration_s, make_trajectory
from sea_hil.errors import SeaHilError
from sea_hil.jit import compiled
from sea_hil.mechanics import limb_params
from sea_hil.offline.drive_kernel import feedback_measurement, make_session_steps
from sea_hil.offline.gc_pause import gc_paused
from sea_hil.offline.session_loop import EngineOptions, SessionLoop
from sea_hil.offline.session_records import SETPOINT_BYTES, STATE_BYTES, EngineResult, SessionRecords
from sea_hil.offline.wire_quantiser import dbc_resolutions
from sea_hil.plant_emulator.disturbance import DisturbanceTable
from sea_hil.plant_emulator.dynamics import State, initial_state
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import LinkEmulator
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.session_summary import session_summary

_log = logging.getLogger("sea_hil.offline")


class _Env:
    """What the sample loop (`sea_hil.offline.session_loop.SessionLoop`) works with: the session's parts."""

    def __init__(self, cfg: SeaHilConfig, mode: str, cycles: int, jit: bool) -> None:
        self.traj = make_trajectory(cfg.trajectory)
        self.period_ns = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.outer_every = max(1, int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz)))
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        # the controller stops at its first state after the cycles (as in lockstep, which runs until it does): lost
        # states delay that by a few samples, a far start pose stretches the lead-in, re-anchors of the edge's
        # trigger restart it; n_max is a safety cap only
        self.n_max = 4 * ((lead_in_ns + self.duration_ns) // self.period_ns + 20 * self.outer_every + 1000
                          + _lead_in_stretch_samples(cfg, self.traj, self.period_ns))
        self.cfg, self.mode = cfg, mode
        self.nominal = nominal_params(cfg)      # the controller's model (the edge and the remote use it)
        self.inner = InnerLoop(cfg, self.nominal, tuple(cfg.plant.initial_theta_rad), 1.0 / cfg.can.feedback_rate_hz)
        seed = cfg.link.seed
        self.uplink = LinkEmulator(cfg.link.uplink, f"{seed}/up")
        self.downlink = LinkEmulator(cfg.link.downlink, f"{seed}/down")
        self.rec = SessionRecords(Keys.from_config(cfg.zenoh))
        self.state_bytes, self.setpoint_bytes = STATE_BYTES, SETPOINT_BYTES
        kernel = compiled(make_session_steps) if jit else None
        self.steps = kernel if kernel is not None else make_session_steps()
        self.jit = kernel is not None
        dl = DriveLimits.from_config(cfg.safety.drive)
        self.drive_limits = (*dl.position_min_rad, *dl.position_max_rad, *dl.velocity_max_rad_s, *dl.spring_force_max_n)
        self.envelope = EnvelopeGate(SetpointEnvelope.from_config(cfg.safety.setpoint), _log)


def _lead_in_stretch_samples(cfg: SeaHilConfig, traj: Any, period_ns: int) -> int:
    """Samples the lead-in from the start pose adds beyond `lead_in_s` (`lead_in_duration_s`: a start far from the
    trajectory stretches it)."""
    tc = cfg.trajectory
    lead_s = lead_in_duration_s(tuple(cfg.plant.initial_theta_rad), traj.sample(0.0), tc.lead_in_s,
                                tc.lead_in_max_velocity_rad_s)
    return int((lead_s - tc.lead_in_s) * 1e9) // period_ns + 1


def with_options(cfg: SeaHilConfig, opts: EngineOptions) -> SeaHilConfig:
    """`cfg` with the trigger placement and delay compensation of `opts` (what the nodes read from their config)."""
    trig = cfg.trigger.model_copy(update={"placement": opts.placement, "edge_check": opts.edge_check,
                                          "edge_model": opts.edge_model})
    ctl = cfg.controller.model_copy(update={"compensation": opts.compensation})
    return cfg.model_copy(update={"trigger": trig, "controller": ctl})


def run_engine(cfg: SeaHilConfig, mode: str, cycles: int = 1, jit: bool = True,
               opts: EngineOptions | None = None) -> EngineResult:
    """`run_session` without cyclic garbage collection (sea_hil/offline/gc_pause.py)."""
    with gc_paused():
        return run_session(cfg, mode, cycles, jit, opts)


def engine_summary(cfg: SeaHilConfig, mode: str, cycles: int = 1) -> dict[str, Any]:
    """summary.json of the session `run_engine(cfg, mode, cycles)` (what a sweep point needs)."""
    return session_summary(run_engine(cfg, mode, cycles).data, mode)


def _prepare(cfg: SeaHilConfig, mode: str, cycles: int, jit: bool
             ) -> tuple[_Env, State, Any, tuple, DisturbanceTable]:
    """A session's parts, its plant's start state and parameters, the DBC resolutions and the disturbance table."""
    p = limb_params(cfg.plant)
    env = _Env(cfg, mode, cycles, jit)
    theta0 = tuple(cfg.plant.initial_theta_rad)
    x: State = initial_state(theta0[0], theta0[1], 0.0, 0.0, p)
    return env, x, p, dbc_resolutions(cfg.can.fd), DisturbanceTable(cfg.disturbance, env.period_ns, cfg.sim.substeps)


def run_session(cfg: SeaHilConfig, mode: str, cycles: int = 1, jit: bool = True,
                opts: EngineOptions | None = None) -> EngineResult:
    """One lockstep-equivalent session of `cycles` measured cycles (after the lead-in); `opts` overrides the config's
    trigger placement and delay compensation (None: the config's)."""
    if opts is not None:
        cfg = with_options(cfg, opts)
    opts = EngineOptions.from_config(cfg)
    env, x, p, lsb, dist = _prepare(cfg, mode, cycles, jit)
    m = feedback_measurement(x, p, lsb)     # the feedback of the current sample, as the edge decodes it
    tab: Any = None
    if opts.placement == "edge":
        env.state_bytes = env.rec.state_bytes = PAYLOAD_SIZE[MsgType.EVENT_STATE]
    loop = SessionLoop(env, opts, cycles)
    saturated, u_max, k, faulted = 0, [0.0, 0.0], 0, False
    while k < env.n_max:
        now = k * env.period_ns
        loop.edge_sample(k, ((m[0], m[1]), (m[2], m[3]), (m[4], m[5]), (m[6], m[7])))
        if not loop.controller(now):
            break
        loop.take_downlink(now)
        nxt = loop.next_k(k)
        if tab is None or nxt > dist.samples:
            tab = dist.upto(nxt) if env.jit else dist.upto(nxt).tolist()
        held = env.inner.deflection_m
        x, m, n_sat, u1m, u2m, bad, env.inner.observer, faulted = env.steps(
            x, k, nxt - k, env.period_ns, cfg.sim.substeps, held or (0.0, 0.0), env.inner.sliding, held is None, p,
            env.nominal, env.inner.gains, env.inner.observer, env.inner.period_s, env.nominal.voltage_limit, tab, lsb,
            env.drive_limits, faulted)
        saturated += n_sat
        u_max = [max(u_max[0], u1m), max(u_max[1], u2m)]
        if bad >= 0:
            raise SeaHilError(f"offline session diverged at sample {bad} (t = {bad * env.period_ns * 1e-9:.3f} s)")
        k = nxt
    env.rec.messages["/can/command"] = [RecordedMessage(0, 0, {"u1_v": u_max[0], "u2_v": u_max[1]})]
    return EngineResult(SessionData(messages=env.rec.messages, complete=True), k, saturated, faulted,
                        env.envelope.rejected, loop.edge)
