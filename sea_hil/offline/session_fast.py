"""The offline session in one compiled call (`sea_hil.offline.session_kernel`): which sessions it covers, the link
draws it needs, and the session's messages built from its records.

Covered: the trigger at the controller without delay compensation (the paper's scheme, the sweep's default), the
gait trajectory, links without a trace or a rate limit. Anything else runs the Python sample loop
(`sea_hil.offline.session_loop`), which gives the same results for the covered sessions
(`tests/test_session_kernel.py`)."""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge_events import tracking_fields
from sea_hil.controller.trajectory import GaitTrajectory
from sea_hil.controller.trigger import NO_EVENT, EventTrigger
from sea_hil.errors import SeaHilError
from sea_hil.jit import compiled
from sea_hil.offline.session_kernel import (
    BAD_SETPOINT,
    DIVERGED,
    Controller,
    Drive,
    Edge,
    Links,
    Records,
    make_session_kernel,
    new_records,
)
from sea_hil.offline.session_records import SETPOINT_BYTES, STATE_BYTES, EngineResult
from sea_hil.protocol.link import LinkEmulator
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason
from sea_hil.recorder.reader import RecordedMessage, SessionData

REASON_NAMES = {int(r): r.name for r in TriggerReason}


def unsupported(cfg: SeaHilConfig, opts: Any, traj: Any) -> str:
    """Why the compiled session cannot run this session ("" = it can)."""
    if opts.placement != "controller" or opts.compensation != "none":
        return f"trigger placement {opts.placement!r} / compensation {opts.compensation!r}"
    if not isinstance(traj, GaitTrajectory):
        return "a CSV trajectory"
    for name, d in (("uplink", cfg.link.uplink), ("downlink", cfg.link.downlink)):
        if d.trace_path or d.rate_bps > 0:
            return f"a {name} trace or rate limit"
    return ""


def delivery_offsets(cfg: LinkDirectionConfig, seed: str, n: int, payload_bytes: int) -> np.ndarray:
    """Delivery time - send time of the first n messages a `LinkEmulator(cfg, seed)` is offered (-1: lost), from the
    emulator itself: without a rate limit or a trace its loss, burst and jitter draws are per message, whatever the
    send times, and only the FIFO rule (`reorder = False`) depends on them, which the kernel applies (`_deliver`)."""
    link = LinkEmulator(cfg.model_copy(update={"reorder": True}), seed)
    at = [link.submit(0, payload_bytes) for _ in range(n)]
    return np.array([-1 if a is None else a for a in at], dtype=np.int64)


def kernel_inputs(env: Any, cfg: SeaHilConfig, x0: tuple, p: Any, lsb: tuple, dist_tab: np.ndarray
                  ) -> tuple[Drive, Edge, Controller, Links, Records]:
    """The kernel's arguments for the session `env` (`session_engine._Env`)."""
    n = env.n_max // env.outer_every + 1          # states the edge can publish
    drive = Drive(x0, p, lsb, env.drive_limits, env.period_ns, cfg.sim.substeps, dist_tab, env.n_max, env.outer_every)
    edge = Edge(env.nominal, env.inner.gains, env.inner.observer, env.inner.period_s, env.nominal.voltage_limit,
                env.envelope.envelope.deflection_max_m, int(round(cfg.safety.setpoint.max_answer_age_s * 1e9)))
    trig = env.make_trigger()
    et = isinstance(trig, EventTrigger)
    ctl = Controller(et, float(trig.threshold) if et else 0.0, float(trig.r) if et else 0.0,
                     int(trig.max_inter_event_ns) if et else 0, env.params, float(env.c), float(env.rho),
                     float(env.boundary_layer), env.traj.rate_rad_s, env.lead_in_ns, env.duration_ns)
    seed, up, down = cfg.link.seed, cfg.link.uplink, cfg.link.downlink
    links = Links(delivery_offsets(up, f"{seed}/up", n, STATE_BYTES), not up.reorder,
                  delivery_offsets(down, f"{seed}/down", n, SETPOINT_BYTES), not down.reorder)
    return drive, edge, ctl, links, new_records(n)


class KernelRun(NamedTuple):
    """A finished kernel call: its records (filled up to the counts) and counters."""
    rec: Records
    k: int
    n_recv: int
    n_sp: int
    n_tr: int
    saturated: int
    u_max_v: tuple[float, float]
    faulted: bool


def run_kernel(env: Any, cfg: SeaHilConfig, x0: tuple, p: Any, lsb: tuple, dist_tab: np.ndarray) -> KernelRun | None:
    """The session on the compiled kernel (the envelope's rejections counted and logged by `env.envelope`; a diverged
    session or a non-finite setpoint a SeaHilError), or None without numba."""
    kernel = compiled(make_session_kernel)
    if kernel is None:
        return None
    drive, edge, ctl, links, rec = kernel_inputs(env, cfg, x0, p, lsb, dist_tab)
    status, k, n_recv, n_sp, n_tr, n_rej, sat, u1_max, u2_max, faulted = kernel(drive, edge, ctl, links, rec)
    sp_f = rec.sp_f[:n_sp]
    for j in rec.rejected[:n_rej].tolist():           # the edge's count and log of rejected setpoints, in order
        if env.envelope.admit(j + 1, (float(sp_f[j, 0]), float(sp_f[j, 1]))):
            raise SeaHilError(f"offline session kernel: setpoint {j + 1} rejected by the kernel, not by the envelope")
    if status == DIVERGED:
        raise SeaHilError(f"offline session diverged at sample {k} (t = {k * env.period_ns * 1e-9:.3f} s)")
    if status == BAD_SETPOINT:      # the payload's own validation says why
        (now, state_seq, code), f = rec.sp_i[n_sp - 1].tolist(), sp_f[n_sp - 1].tolist()
        SetpointPayload(n_sp, now, state_seq, (f[0], f[1]), (f[2], f[3]), TriggerReason(code))
        raise SeaHilError(f"offline session kernel: setpoint {n_sp} is not finite: {f}")
    return KernelRun(rec, k, n_recv, n_sp, n_tr, sat, (u1_max, u2_max), bool(faulted))


def run_compiled(env: Any, cfg: SeaHilConfig, x0: tuple, p: Any, lsb: tuple, dist_tab: np.ndarray
                 ) -> EngineResult | None:
    """The session on the compiled kernel, its messages built from the records, or None without numba."""
    run = run_kernel(env, cfg, x0, p, lsb, dist_tab)
    if run is None:
        return None
    rec = run.rec
    _messages(env.rec, rec, run.n_recv, rec.sp_i[:run.n_sp].tolist(), rec.sp_f[:run.n_sp].tolist(), run.n_tr)
    env.rec.messages["/can/command"] = [RecordedMessage(0, 0, {"u1_v": run.u_max_v[0], "u2_v": run.u_max_v[1]})]
    return EngineResult(SessionData(messages=env.rec.messages, complete=True), run.k, run.saturated, run.faulted,
                        env.envelope.rejected)


def _messages(out: Any, rec: Records, n_recv: int, sp_i: list, sp_f: list, n_tr: int) -> None:
    """The kernel's records as `SessionRecords` messages, in the order the Python loop makes them."""
    pub_ns, pub_fb = rec.pub_ns.tolist(), rec.pub_fb.tolist()
    for i, now in rec.recv[:n_recv].tolist():
        f = pub_fb[i]
        out.state(i + 1, pub_ns[i], ((f[0], f[1]), (f[2], f[3]), (f[4], f[5]), (f[6], f[7])), now)
    for j, ((now, state_seq, code), f) in enumerate(zip(sp_i, sp_f, strict=True)):
        out.setpoint_fields(j + 1, now, state_seq, (f[0], f[1]), (f[2], f[3]), REASON_NAMES[code], now)
    recv_at = {i + 1: now for i, now in rec.recv[:n_recv].tolist()}
    for (t_ns, seq, code, sp_seq), f in zip(rec.tr_i[:n_tr].tolist(), rec.tr_f[:n_tr].tolist(), strict=True):
        name = None if code == NO_EVENT else REASON_NAMES[code]
        out.tracking(tracking_fields(t_ns, seq, (f[0], f[1]), (f[2], f[3]), name, sp_seq), recv_at[seq])
