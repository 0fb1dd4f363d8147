"""Offline engine of a networked session: the lockstep session's timeline in one process, with the same link
emulation, the same wire quantisation and the same summary, fast enough for sweeps of thousands of points.

What it replays, sample by sample (1 ms), as `sea-hil run --lockstep` orders it (docs/sweep.md, "Offline engine"):
the driver boots at rest (`plant.initial_theta_rad`) and integrates each period exactly as `DriverCore.step` does
(the same float expressions and sub-steps, disturbance sampled at the same times); the edge publishes a state every
outer sample through the uplink `LinkEmulator` (same seed stream `<seed>/up`, same payload size), the controller
answers each released state at once (lead-in, trigger, SMC: the live `OuterController` and `LeadIn`), a setpoint
enters the downlink emulator (`<seed>/down`) at that sample and is applied when released; the edge's voltage is the
backstepping law on the DBC-quantised feedback, quantised and saturated as the VOLTAGE_CMD frame does. The per-sample
part (inner law + RK4) runs in a numba kernel compiled from the live functions (`sea_hil.jit`); the outer part in
Python. The messages a recorder would see (states as delivered, setpoints as published, tracking records) are built as
the recorder's `zenoh_record` builds them and summarised by `session_summary`, so the summary is the session's.

Not replayed: wall-clock quantities (latency, loop times), the edge's `/stats`, and `max_abs_voltage_v` is taken up to
the controller's last sample (a session also records the commands of its shut-down tail).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from sea_hil.config import SeaHilConfig
from sea_hil.controller.inner import InnerLoop, inner_step
from sea_hil.controller.nominal import nominal_params
from sea_hil.controller.edge_events import make_trigger, tracking_record
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.outer import OuterController
from sea_hil.controller.predictor import Predictor
from sea_hil.controller.trajectory import LeadIn, make_trajectory
from sea_hil.controller.trigger import EventTrigger, TimeTrigger
from sea_hil.jit import compiled
from sea_hil.mechanics import limb_params
from sea_hil.offline.session_loop import EngineOptions, SessionLoop
from sea_hil.offline.wire_quantiser import dbc_resolutions, quantised
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.dynamics import State, deflections, initial_state, is_finite, saturate
from sea_hil.plant_emulator.integrator import rk4_core
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import DelayQueue, LinkEmulator
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, SetpointPayload, StatePayload, encode
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.errors import SeaHilError

_log = logging.getLogger("sea_hil.offline")
STATE_BYTES, SETPOINT_BYTES = PAYLOAD_SIZE[MsgType.STATE], PAYLOAD_SIZE[MsgType.SETPOINT]


def make_session_steps(fingerprint: str = "") -> Callable[..., tuple]:
    """The per-sample kernel; `fingerprint` (see sea_hil/jit.py) only keys numba's disk cache."""

    def session_steps(x, k0, n_steps, period_ns, substeps, vx, s, hold_measured, p, pn, gains, obs, dt_s,  # noqa
                      limit_v, dist_tab, lsb, lim, faulted):
        """Samples k0 .. k0 + n_steps - 1 from the state x of sample k0: DBC-quantised feedback m -> the edge's
        inner step on its nominal model pn (`inner_step`: disturbance observer state obs, backstepping voltage) ->
        quantised, saturated VOLTAGE_CMD -> one driver period of the plant p (`DriverCore.step`'s expressions; 0 V
        once `faulted`: a drive soft limit `lim` = (theta min x2, theta max x2, |omega| max x2, |spring force| max x2)
        was left, checked on every integrated sample as `DriverCore` does). Returns (x, m of the new x, saturated
        steps, max |u1|, max |u2| commanded, first non-finite sample or -1, obs, faulted)."""
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        sat_count = 0
        u1_max = 0.0
        u2_max = 0.0
        m = feedback_measurement(x, p, lsb)
        for k in range(k0, k0 + n_steps):
            u1, u2, saturated, obs = inner_step(m, vx, s, hold_measured, obs, pn, gains, limit_v, dt_s)
            if saturated:
                sat_count += 1
            u1 = saturate(quantised(u1, lsb[4]), p.voltage_limit)     # the drive's own limit
            u2 = saturate(quantised(u2, lsb[4]), p.voltage_limit)
            u1_max = max(u1_max, abs(u1))
            u2_max = max(u2_max, abs(u2))
            if faulted:             # the drive ignores commands in FAULT: 0 V
                u1 = 0.0
                u2 = 0.0
            t = k * period_ns * 1e-9
            h = (period_ns * 1e-9) / substeps
            for i in range(substeps):
                d = dist_tab[k * substeps + i]
                x = rk4_core(t + i * h, x, (u1, u2), h, p, (d[0], d[1]), (d[2], d[3]), (d[4], d[5]))
            if not is_finite(x):
                return x, m, sat_count, u1_max, u2_max, k, obs, faulted
            if not faulted:
                d1, d2, _, _ = deflections(x, p)
                faulted = not (lim[0] <= x[0] <= lim[2] and lim[1] <= x[1] <= lim[3] and abs(x[2]) <= lim[4]
                               and abs(x[3]) <= lim[5] and abs(p.k1 * d1) <= lim[6] and abs(p.k2 * d2) <= lim[7])
            m = feedback_measurement(x, p, lsb)
        return x, m, sat_count, u1_max, u2_max, -1, obs, faulted

    return session_steps


def feedback_measurement(x: State, p: Any, lsb: tuple[float, float, float, float, float]
                         ) -> tuple[float, float, float, float, float, float, float, float]:
    """(theta1, theta2, omega1, omega2, delta1, delta2, nut_vel1, nut_vel2) of the driver's feedback frames as the
    edge decodes them (DBC resolution; in range). Plain float code: the kernel compiles it."""
    dl1, dl2, _, _ = deflections(x, p)
    return (quantised(x[0], lsb[0]), quantised(x[1], lsb[0]), quantised(x[2], lsb[1]), quantised(x[3], lsb[1]),
            quantised(dl1, lsb[2]), quantised(dl2, lsb[2]), quantised(x[6], lsb[3]), quantised(x[7], lsb[3]))


def driver_disturbance_table(cfg: SeaHilConfig, n_samples: int, period_ns: int) -> np.ndarray:
    """(n_samples * substeps, 6): d(t_i), d(t_i + h/2), d(t_i + h) of every sub-step, sampled in the order and at
    the float times `DriverCore.step` -> `advance` samples them (so a stateful noise disturbance gives the same
    values)."""
    dc, substeps = cfg.disturbance, cfg.sim.substeps
    if dc.kind == "none" or (dc.amplitude_nm[0] == 0.0 and dc.amplitude_nm[1] == 0.0):
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


@dataclass
class EngineResult:
    data: SessionData            # the messages a session's recorder would hold (see module docstring)
    samples: int                 # driver periods simulated
    saturated_steps: int
    drive_faulted: bool = False          # a drive soft limit faulted the drive (0 V from then on)
    setpoints_out_of_envelope: int = 0   # setpoints the edge's envelope rejected


class SessionRecords:
    """What a session's recorder would record of the Zenoh traffic: the dicts `sea_hil.recorder.node.zenoh_record`
    makes of the encoded payloads, built directly (no encode / decode / JSON round trip: float64 fields and JSON
    floats pass unchanged; `tests/test_session_engine.py` checks these dicts equal the recorder's own)."""

    def __init__(self, keys: Keys) -> None:
        self.keys = keys
        self.state_bytes = STATE_BYTES      # EVENT_STATE's size with the trigger at the edge
        self.messages: dict[str, list[RecordedMessage]] = {"/zenoh/state": [], "/zenoh/setpoint": [], "/tracking": []}

    def state(self, seq: int, sample_ns: int, fb: tuple, t_ns: int) -> None:
        (th, om, de, nut) = fb
        self.messages["/zenoh/state"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.state, "seq": seq, "sent_t_ns": sample_ns, "payload_bytes": self.state_bytes,
            "sample_t_ns": sample_ns, "theta1_rad": th[0], "theta2_rad": th[1], "omega1_rad_s": om[0],
            "omega2_rad_s": om[1], "delta1_m": de[0], "delta2_m": de[1], "nut_vel1_m_s": nut[0],
            "nut_vel2_m_s": nut[1]}, seq))

    def setpoint(self, sp: SetpointPayload, t_ns: int) -> None:
        self.messages["/zenoh/setpoint"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.setpoint, "seq": sp.seq, "sent_t_ns": sp.t_ns, "payload_bytes": SETPOINT_BYTES,
            "state_seq": sp.state_seq, "delta1_ref_m": sp.deflection_m[0], "delta2_ref_m": sp.deflection_m[1],
            "s1": sp.sliding[0], "s2": sp.sliding[1], "reason": sp.reason.name}, sp.seq))

    def tracking(self, record: dict[str, Any], t_ns: int) -> None:
        self.messages["/tracking"].append(RecordedMessage(t_ns, t_ns, {**record, "key": self.keys.event},
                                                          record["state_seq"]))


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
        self.inner = InnerLoop(cfg, self.nominal, tuple(cfg.plant.initial_theta_rad), 1.0 / cfg.can.feedback_rate_hz)
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
               opts: EngineOptions | None = None) -> EngineResult:
    """One lockstep-equivalent session of `cycles` measured cycles (after the lead-in); `opts` selects the trigger
    placement and delay compensation (None: the config's, `EngineOptions.from_config`; the paper's scheme is the
    lockstep session bit for bit)."""
    opts = EngineOptions.from_config(cfg) if opts is None else opts
    p = limb_params(cfg.plant)
    env = _Env(cfg, mode, cycles, p, jit)
    theta0 = tuple(cfg.plant.initial_theta_rad)
    x: State = initial_state(theta0[0], theta0[1], 0.0, 0.0, p)
    lsb = dbc_resolutions(cfg.can.fd)
    m = feedback_measurement(x, p, lsb)     # the feedback of the current sample, as the edge decodes it
    dist_tab = driver_disturbance_table(cfg, env.n_max, env.period_ns)
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
                        env.envelope.rejected)

