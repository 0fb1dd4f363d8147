"""summary.json of an offline session straight from the whole-session kernel's records (`session_fast.KernelRun`),
without building its messages: what a sweep point needs, in a few numpy operations instead of ~5,000 message dicts.

It is `sea_hil.report.session_summary.session_summary` of the messages `session_fast.run_compiled` would build
(one limb, no CAN or stats messages), rule for rule: tracking rows unique by state seq (first kept) and sorted by
time (stable), the phase of a state seq (`_phase_of`: its tracking time, else its sample time on the controller's
axis; cycle / lead-in / outside), the counts, blocks and keys. `tests/test_kernel_summary.py` checks the two dicts
are equal (==, floats bit for bit) over links, triggers, lead-ins, disturbances, envelope and fault cases.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from sea_hil.controller.trigger import NO_EVENT
from sea_hil.offline.session_fast import REASON_NAMES, KernelRun
from sea_hil.offline.session_records import SETPOINT_BYTES
from sea_hil.report.limbs import limb_entry, limbs_total
from sea_hil.report.session_summary import rejections_blocks, tracking_or_zero
from sea_hil.report.summary import TIMING_KEY, inter_event_block, transmissions_block
from sea_hil.report.verdict import verdict

CYCLE, LEAD_IN, OUTSIDE = 0, 1, 2
LATENCY_KEYS = ("min", "p50", "p90", "p99", "max")


def _first_of_each(seq: np.ndarray) -> np.ndarray:
    """Indices of the first occurrence of every value of `seq`, in order (`session_summary._unique`)."""
    _, first = np.unique(seq, return_index=True)
    return np.sort(first)


def _lookup(keys: np.ndarray, values: np.ndarray, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(found, value) of every query in the map keys -> values (keys unique)."""
    order = np.argsort(keys, kind="stable")
    sk, sv = keys[order], values[order]
    pos = np.clip(np.searchsorted(sk, query), 0, max(len(sk) - 1, 0))
    found = (sk[pos] == query) if len(sk) else np.zeros(len(query), bool)
    return found, (sv[pos] if len(sk) else np.zeros(len(query), np.int64))


class _Phases:
    """`session_summary._phase_of` over arrays: the phase (CYCLE, LEAD_IN, OUTSIDE) of state seqs."""

    def __init__(self, state_seq: np.ndarray, sample_ns: np.ndarray, tr_seq: np.ndarray, tr_t_ns: np.ndarray) -> None:
        self.state_seq, self.sample_ns, self.tr_seq, self.tr_t_ns = state_seq, sample_ns, tr_seq, tr_t_ns
        known, anchor_ns = _lookup(state_seq, sample_ns, tr_seq)
        self.anchored = bool(known.any())
        if self.anchored:
            a = int(np.argmax(known))                      # the first tracking row whose state was recorded
            self.t0_ns = int(anchor_ns[a]) - int(tr_t_ns[a])
            self.first_ns, self.last_ns = int(tr_t_ns.min()), int(tr_t_ns.max())

    def of(self, seq: np.ndarray) -> np.ndarray:
        out = np.full(len(seq), CYCLE)
        if not self.anchored:
            return out
        tracked, t_tr = _lookup(self.tr_seq, self.tr_t_ns, seq)
        sampled, t_smp = _lookup(self.state_seq, self.sample_ns, seq)
        t = np.where(tracked, t_tr, t_smp - self.t0_ns)
        has_t = tracked | sampled
        cycle = ~has_t | ((t >= 0) & (t <= self.last_ns))
        lead = has_t & ~cycle & (t >= self.first_ns) & (t < 0)
        out[lead] = LEAD_IN
        out[has_t & ~cycle & ~lead] = OUTSIDE
        return out


def kernel_summary(run: KernelRun, state_key: str, state_bytes: int, controller: str) -> dict[str, Any]:
    """summary.json of the kernel's session (see the module docstring); `state_key` the config's state key,
    `state_bytes` a state's payload size."""
    rec = run.rec
    recv = rec.recv[:run.n_recv]
    st_first = _first_of_each(recv[:, 0])
    st_seq = recv[st_first, 0] + 1
    st_sample_ns = rec.pub_ns[recv[st_first, 0]]
    sp_state_seq = rec.sp_i[:run.n_sp, 1]           # setpoint seqs are 1..n_sp: all unique
    tr_i, tr_f = rec.tr_i[:run.n_tr], rec.tr_f[:run.n_tr]
    tr_keep = _first_of_each(tr_i[:, 1])
    tr_i, tr_f = tr_i[tr_keep], tr_f[tr_keep]
    t_s = tr_i[:, 0] * 1e-9
    phases = _Phases(st_seq, st_sample_ns, tr_i[:, 1], np.round(t_s * 1e9).astype(np.int64))
    order = np.argsort(t_s, kind="stable")
    t_s, tr_i, tr_f = t_s[order], tr_i[order], tr_f[order]
    theta, desired = tr_f[:, 0:2], tr_f[:, 2:4]
    event = tr_i[:, 2] != NO_EVENT
    sp_phase, st_phase = phases.of(sp_state_seq), phases.of(st_seq)

    def counts(phase: int) -> dict[str, int]:
        n_down, n_up = int(np.sum(sp_phase == phase)), int(np.sum(st_phase == phase))
        return transmissions_block(n_down, n_down * SETPOINT_BYTES, n_up, n_up * state_bytes)

    lead = t_s < 0
    ev_t, ev_code = t_s[event], tr_i[event, 2]
    ev_keep = ev_t >= 0
    reasons: dict[str, int] = {}
    for code in ev_code[ev_keep].tolist():
        reasons[REASON_NAMES[code]] = reasons.get(REASON_NAMES[code], 0) + 1
    cyc_t = t_s[~lead]
    v = np.abs(np.array([run.u_max_v], dtype=float)).max(axis=0)
    summary: dict[str, Any] = {
        "controller": controller,
        "duration_s": float(cyc_t[-1]) if len(cyc_t) else 0.0,
        "transmissions": counts(CYCLE),
        "lead_in": {"duration_s": float(-t_s[lead][0]) if lead.any() else 0.0, **counts(LEAD_IN),
                    "tracking": tracking_or_zero(theta[lead], desired[lead])},
        "uplink_outside_msgs": int(np.sum(st_phase == OUTSIDE)),
        "events_by_reason": dict(sorted(reasons.items())),
        "tracking": tracking_or_zero(theta[~lead], desired[~lead]),
        "inter_event_s": inter_event_block(ev_t[ev_keep]),
        "max_abs_voltage_v": [float(v[0]), float(v[1])],
        "edge": {},
        "rejections": rejections_blocks({})[0],     # the engine has no edge /stats (as session_summary of its data)
        TIMING_KEY: {"latency_us": {k: -1.0 for k in LATENCY_KEYS}, "latency_samples": 0, "edge": {},
                     "rejections": rejections_blocks({})[1]},
    }
    name = state_key.split("/")[-2] if run.n_recv else "limb1"
    entries = [limb_entry(name, 1, "", summary)]
    summary["limbs"], summary["limbs_total"] = entries, limbs_total(entries)
    summary["drive_faults"] = []   # as `session_summary` of the engine's messages (no heartbeats recorded)
    summary["verdict"] = verdict({**summary, "lockstep": True})
    return summary
