"""Offline engine of a networked session: the lockstep session's timeline in one process, composed of the nodes' own
cores and the same link emulation, wire quantisation and summary, fast enough for sweeps of thousands of points.

What it runs, sample by sample (1 ms), in the order `sea-hil run --lockstep` does (docs/sweep.md, "Offline
engine"): the edge's core (`EdgeCore`, controller/edge_core.py) takes each sample the loop stops at (an outer sample,
every sample with `trigger.edge_check = "sample"`, or a sample a link delivers at), publishes states through its
uplink `LinkEmulator` (seed stream `<seed>/up`) stamped as lockstep stamps them (the release sample), the
controller's core (`ControllerCore`, controller/remote_core.py) answers each released state at once, its setpoint
payload enters the edge core's intake (checks, envelope, downlink emulator `<seed>/down`) and is applied when
released. Between those samples the edge's inner step and the driver's period run in one compiled call per stretch
(`drive_kernel.session_steps`: the edge core's own `InnerLoop` state and `inner_step`, the VOLTAGE_CMD quantisation
and saturation, `DriverCore.step`'s RK4 sub-steps on `rk4_core` with the one disturbance table, the drive soft
limits). The messages a recorder would see (states as delivered, setpoints as published, tracking records) are built
as the recorder's `zenoh_record` builds them (`SessionRecords`) and summarised by `session_summary`, so the summary
is the session's (tests/test_engine_lockstep.py: bit for bit, over a matrix of links, schemes and faults).

The edge core's final `/stats` record is in the messages too (`EdgeCore.stats`, the kernel's samples counted in by
`EdgeCore.ran_elsewhere`), so `session_summary` builds the `edge` block, the rejections and the verdict by lockstep's
rule. Not replayed: wall-clock quantities (latency, loop times: `loop_count` is 0), and `max_abs_voltage_v` is taken
up to the controller's last sample (a session also records the commands of its shut-down tail).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_core import EdgeCore
from sea_hil.controller.edge_events import EdgeEvents
from sea_hil.controller.remote_core import ControllerCore
from sea_hil.controller.trajectory import lead_in_duration_s, make_trajectory
from sea_hil.dynamics import initial_state
from sea_hil.errors import SeaHilError
from sea_hil.jit import compiled, entry
from sea_hil.mechanics import limb_params
from sea_hil.offline.drive_kernel import feedback_measurement, make_session_steps
from sea_hil.offline.gc_pause import gc_paused
from sea_hil.offline.wire_quantiser import dbc_resolutions
from sea_hil.plant_emulator.disturbance import DisturbanceTable
from sea_hil.plant_emulator.soft_limits import DriveLimits
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Feedback, Heartbeat
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import release_sample_ns
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, SetpointPayload, StatePayload, decode
from sea_hil.recorder.meta import ENGINE_SESSION_META, META_SESSION
from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.session_summary import session_summary
from sea_hil.stats.schema import stats_record

STATE_BYTES, SETPOINT_BYTES = PAYLOAD_SIZE[MsgType.STATE], PAYLOAD_SIZE[MsgType.SETPOINT]


@dataclass(frozen=True)
class EngineOptions:
    """Overrides of the config's control scheme (`with_options`)."""
    placement: str = "controller"       # controller | edge
    compensation: str = "none"          # none | predict
    edge_check: str = "outer"           # outer | sample: how often the edge evaluates its trigger
    edge_model: bool = False            # the edge's lookahead runs the nominal model (else: extrapolation)

    def __post_init__(self) -> None:
        if self.placement not in ("controller", "edge") or self.compensation not in ("none", "predict") \
                or self.edge_check not in ("outer", "sample"):
            raise ValueError(f"bad engine options {self}")

    @classmethod
    def from_config(cls, cfg: SeaHilConfig) -> EngineOptions:
        """The options a config selects (`trigger.placement`, `trigger.edge_check`, `trigger.edge_model`,
        `controller.compensation`)."""
        t = cfg.trigger
        return cls(placement=t.placement, compensation=cfg.controller.compensation, edge_check=t.edge_check,
                   edge_model=t.edge_model)


def with_options(cfg: SeaHilConfig, opts: EngineOptions) -> SeaHilConfig:
    """`cfg` with the trigger placement and delay compensation of `opts` (what the nodes read from their config)."""
    trig = cfg.trigger.model_copy(update={"placement": opts.placement, "edge_check": opts.edge_check,
                                          "edge_model": opts.edge_model})
    ctl = cfg.controller.model_copy(update={"compensation": opts.compensation})
    return cfg.model_copy(update={"trigger": trig, "controller": ctl})


@dataclass
class EngineResult:
    data: SessionData            # the messages a session's recorder would hold (see module docstring)
    samples: int                 # driver periods simulated
    saturated_steps: int
    drive_faulted: bool = False          # a drive soft limit faulted the drive (0 V from then on)
    setpoints_out_of_envelope: int = 0   # setpoints the edge's envelope rejected
    edge: EdgeEvents | None = None       # trigger at the edge: the edge core's events (stats, stale holds)
    edge_stats: dict[str, Any] = field(default_factory=dict)   # the edge core's final counters (`EdgeCore.stats`)


class SessionRecords:
    """What a session's recorder would record of the Zenoh traffic: the dicts `sea_hil.recorder.node.zenoh_record`
    makes of the encoded payloads, built directly from the decoded payloads (float64 fields and JSON floats pass
    unchanged; `tests/test_session_engine.py` checks these dicts equal the recorder's own)."""

    def __init__(self, keys: Keys, state_bytes: int = STATE_BYTES) -> None:
        self.keys = keys
        self.state_bytes = state_bytes      # EVENT_STATE's size with the trigger at the edge
        self.messages: dict[str, list[RecordedMessage]] = {"/zenoh/state": [], "/zenoh/setpoint": [], "/tracking": []}

    def state(self, p: StatePayload, t_ns: int) -> None:
        th, om, de, nut = p.theta_rad, p.omega_rad_s, p.delta_m, p.nut_vel_m_s
        self.messages["/zenoh/state"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.state, "seq": p.seq, "sent_t_ns": p.sample_t_ns, "payload_bytes": self.state_bytes,
            "sample_t_ns": p.sample_t_ns, "theta1_rad": th[0], "theta2_rad": th[1], "omega1_rad_s": om[0],
            "omega2_rad_s": om[1], "delta1_m": de[0], "delta2_m": de[1], "nut_vel1_m_s": nut[0],
            "nut_vel2_m_s": nut[1]}, p.seq))

    def setpoint(self, sp: SetpointPayload, t_ns: int) -> None:
        self.messages["/zenoh/setpoint"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.setpoint, "seq": sp.seq, "sent_t_ns": sp.t_ns, "payload_bytes": SETPOINT_BYTES,
            "state_seq": sp.state_seq, "delta1_ref_m": sp.deflection_m[0], "delta2_ref_m": sp.deflection_m[1],
            "s1": sp.sliding[0], "s2": sp.sliding[1], "reason": sp.reason.name}, sp.seq))

    def tracking(self, record: dict[str, Any], t_ns: int) -> None:
        self.messages["/tracking"].append(RecordedMessage(t_ns, t_ns, {**record, "key": self.keys.event},
                                                          record["state_seq"]))


def run_engine(cfg: SeaHilConfig, mode: str, cycles: int = 1, opts: EngineOptions | None = None) -> EngineResult:
    """`run_session` without cyclic garbage collection (sea_hil/offline/gc_pause.py)."""
    with gc_paused():
        return run_session(cfg, mode, cycles, opts)


def engine_summary(cfg: SeaHilConfig, mode: str, cycles: int = 1) -> dict[str, Any]:
    """summary.json of the session `run_engine(cfg, mode, cycles)` (what a sweep point needs), its messages built and
    summarised without cyclic garbage collection too (sea_hil/offline/gc_pause.py)."""
    with gc_paused():
        res = run_session(cfg, mode, cycles)
        return result_summary(res, mode, cfg)


def result_summary(res: EngineResult, mode: str, cfg: SeaHilConfig) -> dict[str, Any]:
    """summary.json of an engine session: `session_summary` of its messages (the edge block, rejections, drive
    latches and verdict from the edge core's final `/stats` record, as lockstep's), judged under `cfg`'s
    `[verdict]`."""
    return session_summary(res.data, mode, verdict_cfg=cfg.verdict)


def run_session(cfg: SeaHilConfig, mode: str, cycles: int = 1, opts: EngineOptions | None = None) -> EngineResult:
    """One lockstep-equivalent session of `cycles` measured cycles (after the lead-in); `opts` overrides the config's
    trigger placement and delay compensation (None: the config's)."""
    if opts is not None:
        cfg = with_options(cfg, opts)
    # the measured cycles: the edge's trigger records no tracking after them (as `sea-hil run` sets it)
    cfg = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"cycles": cycles})})
    return _Session(cfg, mode, cycles).run()


def _lead_in_stretch_samples(cfg: SeaHilConfig, traj: Any, period_ns: int) -> int:
    """Samples the lead-in from the start pose adds beyond `lead_in_s` (`lead_in_duration_s`: a start far from the
    trajectory stretches it)."""
    tc = cfg.trajectory
    lead_s = lead_in_duration_s(cfg.plant.initial_theta_rad, traj.sample(0.0), tc.lead_in_s,
                                tc.lead_in_max_velocity_rad_s)
    return int((lead_s - tc.lead_in_s) * 1e9) // period_ns + 1


class _Session:
    """One offline session: the edge's and the controller's cores, the plant's state, the records."""

    NODE_ID = 1

    def __init__(self, cfg: SeaHilConfig, mode: str, cycles: int) -> None:
        self.cfg, self.mode = cfg, mode
        traj = make_trajectory(cfg.trajectory)
        self.period_ns = period = int(round(1e9 / cfg.can.feedback_rate_hz))
        self.outer_every = max(1, int(round(cfg.controller.sample_period_s * cfg.can.feedback_rate_hz)))
        duration_ns = int(round(traj.period_s * cycles * 1e9))
        lead_in_ns = int(round(cfg.trajectory.lead_in_s * 1e9))
        # the controller stops at its first state after the cycles (lockstep runs until it does): lost states delay
        # that by a few samples, a far start pose stretches the lead-in, re-anchors of the edge's trigger restart
        # it; n_max is a safety cap only
        self.n_max = 4 * ((lead_in_ns + duration_ns) // period + 20 * self.outer_every + 1000
                          + _lead_in_stretch_samples(cfg, traj, period))
        state_bytes = PAYLOAD_SIZE[MsgType.EVENT_STATE] if cfg.trigger.placement == "edge" else STATE_BYTES
        self.rec = SessionRecords(Keys.from_config(cfg.zenoh), state_bytes)
        self.now = 0
        self.released: list[bytes] = []        # state payloads the uplink emulator has released (to the controller)
        self.edge = EdgeCore(cfg, self.NODE_ID, mode=mode, state_sink=self.released.append,
                             record_sink=lambda record: self.rec.tracking(record, self.now),
                             stamp=lambda at_ns: release_sample_ns(at_ns, period),   # as `LockstepEdgeSync`
                             restart_possible=lambda timed_out: False, epoch=0, wall_ns=lambda: self.now)
        self.controller = ControllerCore(cfg, mode, cycles=cycles)
        # the edge core's trigger checks every 1 kHz sample (`trigger.edge_check = "sample"`; never TT: EdgeEvents)
        self.every_sample = self.edge.events is not None and self.edge.events.every_sample
        self.newest = 0
        self.p = limb_params(cfg.plant)
        theta0 = tuple(cfg.plant.initial_theta_rad)
        self.x = initial_state(theta0[0], theta0[1], 0.0, 0.0, self.p)
        self.lsb = dbc_resolutions(cfg.can.fd)
        self.dist = DisturbanceTable(cfg.disturbance, period, cfg.sim.substeps)
        self.drive_limits = DriveLimits.from_config(cfg.safety.drive)
        kernel = compiled(make_session_steps)
        self.jit = kernel is not None          # without numba the same body runs as plain Python (on lists)
        self.steps = kernel if kernel is not None else make_session_steps()

    def run(self) -> EngineResult:
        cfg, edge, inner = self.cfg, self.edge, self.edge.inner
        m = feedback_measurement(self.x, self.p, self.lsb)  # the feedback of the current sample, as the edge decodes it
        saturated, u1_max, u2_max, k, faulted, finished, told = 0, 0.0, 0.0, 0, 0, False, False
        tab: Any = None
        steps: Any = None
        substeps, period, x, n_max, node_id = cfg.sim.substeps, self.period_ns, self.x, self.n_max, self.NODE_ID
        p, pn, gains, dt_s, lsb, limits = self.p, inner._p, inner.gains, inner.period_s, self.lsb, self.drive_limits
        while k < n_max:
            self.now = now = k * period
            fb = Feedback(node_id, k & 0xFF, (now // 1000) & 0xFFFF, (m[0], m[1]), (m[2], m[3]), (m[4], m[5]),
                          (m[6], m[7]))
            edge.accept(fb, 0)
            if faulted and not told:   # the drive latched in the last stretch: its heartbeat, at the next sample
                told = True
                edge.on_heartbeat(self._fault_heartbeat(faulted))
            edge.publish(fb)
            edge.poll(now)
            if self.released and not self._controller(now):
                finished = True
                break
            edge.take_downlink(now)
            nxt = self._next_k(k)
            if tab is None or nxt > self.dist.samples:
                tab = self.dist.upto(nxt) if self.jit else self.dist.upto(nxt).tolist()
            held = inner.deflection_m
            args = (x, k, nxt - k, period, substeps, held or (0.0, 0.0), inner.sliding, held is None, p, pn, gains,
                    inner.observer, dt_s, pn.voltage_limit, tab, lsb, limits, faulted)
            steps = entry(self.steps, args) if steps is None else steps   # the types stay these (`entry`)
            x, m, n_sat, u1m, u2m, bad, inner.observer, faulted = steps(*args)
            saturated += n_sat
            edge.ran_elsewhere(nxt - k - 1, nxt - k, n_sat)   # samples k+1..nxt-1 accepted, k..nxt-1 commanded
            u1_max, u2_max = max(u1_max, u1m), max(u2_max, u2m)
            if bad >= 0:
                raise SeaHilError(f"offline session diverged at sample {bad} (t = {bad * period * 1e-9:.3f} s)")
            k = nxt
        if finished:     # lockstep's edge answers the sample at which the controller finished (its inner step is
            edge.ran_elsewhere(0, 1, 0)    # not simulated here: the session ends)
        if faulted:      # still latched at the end: the drive's last heartbeat
            edge.on_heartbeat(self._fault_heartbeat(faulted))
        self.rec.messages["/can/command"] = [RecordedMessage(0, 0, {"u1_v": u1_max, "u2_v": u2_max})]
        stats = edge.stats()
        # the edge's final /stats record, as lockstep's edge writes it at its last sample time (`record_edge_finals`)
        end_ns = edge.sample_t_ns
        self.rec.messages["/stats"] = [RecordedMessage(end_ns, end_ns, stats_record("edge", stats, final=True,
                                                                                    t_ns=end_ns))]
        data = SessionData(messages=self.rec.messages, metadata={META_SESSION: ENGINE_SESSION_META}, complete=True)
        return EngineResult(data, k, saturated, bool(faulted), edge.envelope.rejected, edge.events, stats)

    def _fault_heartbeat(self, bits: int) -> Heartbeat:
        """The HEARTBEAT of a drive in FAULT with the soft-limit `bits` the kernel latched (the engine emulates no
        heartbeat period: the edge core sees one at the sample after the fault and one at the end)."""
        return Heartbeat(self.NODE_ID, DriverState.FAULT, ErrorFlags(bits), 0, 0, 0)

    def _controller(self, now: int) -> bool:
        """The controller's core answers the states released by `now`. Every released state is on the uplink key (the
        recorder sees it); one released after a newer one is ignored, as the live controller's sequence check does,
        and counted (`uplink_out_of_order`, as `LockstepEdgeSync` counts it); False when it has finished its
        cycles."""
        released, self.released[:] = list(self.released), []
        for data in released:
            p = decode(data)
            assert isinstance(p, StatePayload)   # the edge core's uplink carries its state payloads only
            self.rec.state(p, now)
            if p.seq <= self.newest:
                self.edge.counters.uplink_out_of_order += 1
                continue
            self.newest = p.seq
            ans = self.controller.on_state(p, _stamp, lambda: now)
            if ans is None:
                return False
            for _channel, msg in ans.messages:
                sp = decode(msg)
                assert isinstance(sp, SetpointPayload)   # the edge holds the inner loop: setpoints only
                self.rec.setpoint(sp, now)
                self.edge.on_downlink(msg)
            if ans.record is not None:
                self.rec.tracking(ans.record, now)     # as the recorder decodes its JSON (floats round-trip)
        return True

    def _next_k(self, k: int) -> int:
        """The next sample after k at which something happens: an outer sample (every sample with the edge's
        trigger checked at 1 kHz), or a delivery of either link."""
        if self.every_sample:
            return k + 1
        nxt = min((k // self.outer_every + 1) * self.outer_every, self.n_max)
        for due in (self.edge.publisher.uplink.next_due_ns(), self.edge.intake.pending.next_due_ns()):
            if due is not None and due < nxt * self.period_ns:
                nxt = max(k + 1, -(-due // self.period_ns))
        return nxt


def _stamp(p: StatePayload) -> int:
    """A state's arrival on the simulated clock: its header stamp (the release sample, `LockstepEdgeSync.state_stamp`)."""
    return p.t_ns

