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

import numpy as np

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_events import make_trigger, tracking_record
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.inner import InnerLoop
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.outer import OuterController
from sea_hil.controller.predictor import Predictor
from sea_hil.controller.trajectory import LeadIn, make_trajectory
from sea_hil.controller.trigger import EventTrigger, TimeTrigger
from sea_hil.dynamics import State, initial_state
from sea_hil.errors import SeaHilError
from sea_hil.fault_explain import POLICY_USER
from sea_hil.jit import compiled
from sea_hil.mechanics import limb_params
from sea_hil.offline.drive_kernel import feedback_measurement, make_session_steps
from sea_hil.offline.gc_pause import gc_paused
from sea_hil.offline.kernel_summary import kernel_summary
from sea_hil.offline.session_fast import run_compiled, run_kernel, unsupported
from sea_hil.offline.session_loop import EngineOptions, SessionLoop
from sea_hil.offline.session_records import SETPOINT_BYTES, STATE_BYTES, EngineResult, SessionRecords
from sea_hil.offline.wire_quantiser import dbc_resolutions
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, SetpointPayload
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.session_summary import session_summary
from sea_hil.report.verdict import verdict

__all__ = ["driver_disturbance_table", "engine_summary", "run_engine"]

_log = logging.getLogger("sea_hil.offline")


def driver_disturbance_table(cfg: SeaHilConfig, n_samples: int, period_ns: int) -> np.ndarray:
    """(n_samples * substeps, 6): d(t_i), d(t_i + h/2), d(t_i + h) of every sub-step, sampled in the order and at
    the float times `DriverCore.step` -> `advance` samples them (so a stateful noise disturbance gives the same
    values)."""
    dc, substeps = cfg.disturbance, cfg.sim.substeps
    if dc.is_zero():        # every joint, incl. per-joint tables ([disturbance.hip] / [disturbance.knee])
        return np.zeros((n_samples * substeps, 6))
    dist = make_disturbance(dc)
    h = (period_ns * 1e-9) / substeps
    hh = 0.5 * h
    out = np.empty((n_samples * substeps, 6))
    for k in range(n_samples):
        t = k * period_ns * 1e-9
        for i in range(substeps):
            ti = t + i * h
            out[k * substeps + i] = (*dist(ti), *dist(ti + hh), *dist(ti + h))
    return out


class _Env:
    """What the sample loop (`sea_hil.offline.session_loop.SessionLoop`) works with: the session's parts."""

    def __init__(self, cfg: SeaHilConfig, mode: str, cycles: int, p: Any, jit: bool) -> None:
        cc = cfg.controller
        self.c, self.rho, self.boundary_layer = cc.c, cc.rho, cc.boundary_layer
        self.traj = make_trajectory(cfg.trajectory)
        self.period_ns = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.outer_every = max(1, int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz)))
        self.duration_ns = int(round(self.traj.period_s * cycles * 1e9))
        self.lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        # the controller stops at its first state after the cycles; lost states delay that by a few samples only
        self.n_max = (self.lead_in_ns + self.duration_ns) // self.period_ns + 20 * self.outer_every + 1000
        self.cfg, self.mode = cfg, mode
        self.params = nominal_params(cfg)    # the remote controller's (and the edge's) nominal model
        self.outer = OuterController(cfg, self.params, mode)
        self.nominal = nominal_params(cfg)      # the controller's model (the edge and the remote use it)
        self.inner = InnerLoop(cfg, self.nominal, cfg.plant.initial_theta_rad, 1.0 / cfg.can.feedback_rate_hz)
        seed = cfg.link.seed
        self.uplink = LinkEmulator(cfg.link.uplink, f"{seed}/up")
        self.downlink = LinkEmulator(cfg.link.downlink, f"{seed}/down")
        self.rec = SessionRecords(Keys.from_config(cfg.zenoh))
        self.state_bytes, self.setpoint_bytes = STATE_BYTES, SETPOINT_BYTES
        self.tracking_record = tracking_record
        kernel = compiled(make_session_steps) if jit else None
        self.steps = kernel if kernel is not None else make_session_steps()
        self.jit = kernel is not None
        self.predictor: Predictor | None = None
        dl = DriveLimits.from_config(cfg.safety.drive)
        self.drive_limits = (*dl.position_min_rad, *dl.position_max_rad, *dl.velocity_max_rad_s, *dl.spring_force_max_n)
        self.envelope = EnvelopeGate(SetpointEnvelope.from_config(cfg.safety.setpoint), _log)

    def lead_in(self, fb: tuple) -> LeadIn:
        return LeadIn(fb[0], fb[1], self.traj.sample(0.0), self.lead_in_ns * 1e-9)

    def make_trigger(self) -> EventTrigger | TimeTrigger:
        return make_trigger(self.cfg, self.mode)

    @staticmethod
    def downlink_due(queue: DelayQueue[SetpointPayload], now_ns: int) -> list[SetpointPayload]:
        return queue.pop_due(now_ns)


def run_engine(cfg: SeaHilConfig, mode: str, cycles: int = 1, jit: bool = True,
               opts: EngineOptions | None = None, whole: bool = True) -> EngineResult:
    """`run_session` without cyclic garbage collection (sea_hil/offline/gc_pause.py)."""
    with gc_paused():
        return run_session(cfg, mode, cycles, jit, opts, whole)


def engine_summary(cfg: SeaHilConfig, mode: str, cycles: int = 1) -> dict[str, Any]:
    """summary.json of the session `run_engine(cfg, mode, cycles)` (what a sweep point needs), without cyclic garbage
    collection: where the compiled kernel covers it, straight from the kernel's records
    (`sea_hil.offline.kernel_summary`, no messages built), else `session_summary` of the engine's messages; the
    same dict either way (tests/test_kernel_summary.py)."""
    with gc_paused():
        opts = EngineOptions.from_config(cfg)
        env, x, p, lsb, dist_tab = _prepare(cfg, mode, cycles, True)
        if not unsupported(cfg, opts, env.traj):
            run = run_kernel(env, cfg, x, p, lsb, dist_tab)
            if run is not None:
                return engine_verdict(kernel_summary(run, env.rec.keys.state, env.rec.state_bytes, mode),
                                      run.faulted, run.saturated, run.k, cfg)
        res = run_session(cfg, mode, cycles, opts=opts)
        return engine_verdict(session_summary(res.data, mode), res.drive_faulted, res.saturated_steps, res.samples,
                              cfg)


def engine_verdict(summary: dict[str, Any], faulted: bool, saturated_steps: int, samples: int, cfg: SeaHilConfig
                   ) -> dict[str, Any]:
    """`summary` with the engine's `drive_faults` (the engine knows only whether a soft limit faulted the drive, not
    when: `t_s` None) and its `verdict` under `cfg`'s `[verdict]`, judging the saturated inner steps too (of
    `samples` driver periods; the engine's summary has no edge counters)."""
    faults = [{"node_id": 1, "t_s": None, "state": "FAULT", "flags": ["soft limit"], "in_fault_s": None,
               "cleared": False, "clear_policy": POLICY_USER}] if faulted else []
    out = {**summary, "drive_faults": faults}
    edge = {**out.get("edge", {}), "saturated_steps": saturated_steps, "commands_sent": samples}
    out["verdict"] = verdict({**out, "lockstep": True, "edge": edge}, cfg.verdict)
    return out


def _prepare(cfg: SeaHilConfig, mode: str, cycles: int, jit: bool) -> tuple[_Env, State, Any, tuple, np.ndarray]:
    """A session's parts, its plant's start state and parameters, the DBC resolutions and the disturbance table."""
    p = limb_params(cfg.plant)
    env = _Env(cfg, mode, cycles, p, jit)
    theta0 = tuple(cfg.plant.initial_theta_rad)
    x: State = initial_state(theta0[0], theta0[1], 0.0, 0.0, p)
    return env, x, p, dbc_resolutions(cfg.can.fd), driver_disturbance_table(cfg, env.n_max, env.period_ns)


def run_session(cfg: SeaHilConfig, mode: str, cycles: int = 1, jit: bool = True,
                opts: EngineOptions | None = None, whole: bool = True) -> EngineResult:
    """One lockstep-equivalent session of `cycles` measured cycles (after the lead-in); `opts` selects the trigger
    placement and delay compensation (None: the config's, `EngineOptions.from_config`; the paper's scheme is the
    lockstep session bit for bit). `whole` (with `jit`): the session in one compiled call where it covers the options
    (`sea_hil.offline.session_fast`), else (and with whole=False) the Python sample loop; both give the same result."""
    opts = EngineOptions.from_config(cfg) if opts is None else opts
    env, x, p, lsb, dist_tab = _prepare(cfg, mode, cycles, jit)
    if whole and jit and not unsupported(cfg, opts, env.traj):
        res = run_compiled(env, cfg, x, p, lsb, dist_tab)
        if res is not None:
            return res
    m = feedback_measurement(x, p, lsb)     # the feedback of the current sample, as the edge decodes it
    tab = dist_tab if env.jit else dist_tab.tolist()
    if opts.compensation == "predict":
        env.predictor = Predictor.for_inner(env.inner, env.period_ns, cfg.sim.substeps, jit=env.jit)
    if opts.placement == "edge":
        env.state_bytes = env.rec.state_bytes = PAYLOAD_SIZE[MsgType.EVENT_STATE]
    loop = SessionLoop(env, opts)
    saturated, u_max, k, faulted = 0, [0.0, 0.0], 0, False
    while k < env.n_max:
        now = k * env.period_ns
        loop.edge_sample(k, ((m[0], m[1]), (m[2], m[3]), (m[4], m[5]), (m[6], m[7])))
        if not loop.controller(now):
            break
        loop.take_downlink(now)
        nxt = loop.next_k(k)
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
