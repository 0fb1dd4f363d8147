"""Delay compensation by prediction (issue 16): the controller computes v_x for the state at the
instant its setpoint will act, by integrating its nominal model (plant + the edge's inner loop at 1 kHz) forward from
the received state over the delay, with the setpoints it has already sent applied at their estimated arrival times.

The delay: states carry their sample time and the clocks are taken as synchronised (in a session: PTP/chrony on the
two hosts; here the simulated clock), so the uplink delay of each state is measured on arrival; the downlink delay
is not observable by the controller alone and is estimated as the smoothed uplink delay (a symmetric link). When the
delay varies, each prediction uses the state's own measured uplink delay for the past and the smoothed estimate for
the future; an error in the estimate shifts when the predicted setpoint acts, by at most the jitter.

The nominal model is the shared SEA dynamics (`sea_hil.dynamics`, Eq. 1-9, with the controller's nominal parameters)
closed by the edge's inner step (`inner_step`, observer off: it has no model of the disturbance), exact feedback, no
drive limits, no disturbance; it runs in a numba kernel compiled from those functions (`sea_hil.jit`) when numba is
installed, the same body in plain Python otherwise. The live remote controller (controller/remote.py), the edge's
model lookahead (controller/edge_trigger.py) and the offline session engine all use this one class.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sea_hil.config.base import Pair
from sea_hil.controller.backstepping import InnerGains
from sea_hil.controller.inner import inner_step
from sea_hil.controller.observer import OBSERVER_UNSTARTED, ObserverState
from sea_hil.controller.smc import JointState
from sea_hil.dynamics import State, deflections, rk4_core, saturate
from sea_hil.jit import compiled, entry
from sea_hil.mechanics import LimbParams, sea_geometry


def make_predict_steps(fingerprint: str = "") -> Callable[..., State]:
    """The nominal closed loop, `n_steps` samples from the state x of sample k0, the setpoint (vx, s) held (or the
    measured deflection when `hold_measured`); `fingerprint` (sea_hil/jit.py) only keys numba's disk cache."""

    def predict_steps(x: State, k0: int, n_steps: int, period_ns: int, substeps: int, vx: Pair, s: Pair,
                      hold_measured: bool, p: LimbParams, gains: InnerGains, obs: ObserverState, dt_s: float) -> State:
        fingerprint  # noqa: B018  (a closure cell: part of numba's cache key)
        for k in range(k0, k0 + n_steps):
            dl1, dl2, _, _ = deflections(x, p)
            m = (x[0], x[1], x[2], x[3], dl1, dl2, x[6], x[7])
            u1, u2, _, obs = inner_step(m, vx, s, hold_measured, obs, p, gains, p.voltage_limit, dt_s)
            u1 = saturate(u1, p.voltage_limit)
            u2 = saturate(u2, p.voltage_limit)
            t = k * period_ns * 1e-9
            h = (period_ns * 1e-9) / substeps
            for i in range(substeps):
                x = rk4_core(t + i * h, x, (u1, u2), h, p, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))
        return x

    return predict_steps


def predict_kernel(jit: bool = True) -> Callable[..., State]:
    kernel = compiled(make_predict_steps) if jit else None
    return kernel if kernel is not None else make_predict_steps()


MAX_HORIZON_NS = 500_000_000   # a delay beyond this is a clock error (unsynchronised clocks), not a link: clamped


@dataclass
class Predictor:
    params: LimbParams            # the controller's nominal model
    gains: Any                    # the inner loop's InnerGains
    dt_s: float                   # the inner loop's period
    period_ns: int
    substeps: int
    jit: bool = True
    schedule: list[tuple[int, tuple[float, float], tuple[float, float]]] = field(default_factory=list)
    down_delay_ns: float | None = None
    predictions: int = 0
    clamped: int = 0              # delays/horizons outside [0, MAX_HORIZON_NS] (clock skew), clamped and counted

    def __post_init__(self) -> None:
        self.kernel = predict_kernel(self.jit)
        self._call: Callable[..., tuple[Any, ...]] | None = None    # the kernel's entry point for this predictor's types
        self._gains = self.gains._replace(compensation=0)   # the nominal closed loop without the edge's observer

    def warm(self, theta_rad: tuple[float, float]) -> None:
        """Compile (or load from numba's disk cache) the kernel now, with one prediction from rest at `theta_rad`:
        a node calls this before its loop, so no real-time sample pays for it."""
        self.predict((theta_rad, (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)), 0, self.period_ns, count=False)

    @classmethod
    def for_inner(cls, inner: Any, period_ns: int, substeps: int, jit: bool = True) -> Predictor:
        """The predictor of the nominal closed loop with the edge's inner loop `inner` (an `InnerLoop`)."""
        return cls(inner._p, inner.gains, inner.period_s, period_ns, substeps, jit=jit)

    def observe_uplink(self, delay_ns: int) -> None:
        if not 0 <= delay_ns <= MAX_HORIZON_NS:
            self.clamped += 1
            delay_ns = min(max(delay_ns, 0), MAX_HORIZON_NS)
        self.down_delay_ns = float(delay_ns) if self.down_delay_ns is None else (
            0.875 * self.down_delay_ns + 0.125 * delay_ns)

    def apply_time_ns(self, now_ns: int) -> int:
        """When a setpoint sent now is expected to act at the edge (on a sample boundary)."""
        est = now_ns + int(self.down_delay_ns or 0.0)
        return -(-est // self.period_ns) * self.period_ns

    def sent(self, apply_ns: int, vx: tuple[float, float], s: tuple[float, float]) -> None:
        self.schedule.append((apply_ns, vx, s))
        if len(self.schedule) > 64:
            del self.schedule[:-64]

    def predict_held(self, fb: tuple[tuple[float, float], ...], sample_ns: int, until_ns: int,
                     hold: tuple[tuple[float, float], tuple[float, float]] | None) -> JointState:
        """The edge's view: the state at `until_ns` with the setpoint it holds now kept (None: hold measured)."""
        saved = self.schedule
        self.schedule = [] if hold is None else [(sample_ns, hold[0], hold[1])]
        try:
            return self.predict(fb, sample_ns, until_ns, count=False)
        finally:
            self.schedule = saved

    def predict(self, fb: tuple[tuple[float, float], ...], sample_ns: int, until_ns: int,
                count: bool = True) -> JointState:
        """The joint state at `until_ns` from the feedback `fb` (theta, omega, delta, nut velocity) of `sample_ns`."""
        (q1, q2), (w1, w2), (d1, d2), (nv1, nv2) = fb
        if until_ns - sample_ns > MAX_HORIZON_NS:
            self.clamped += count
            until_ns = sample_ns + MAX_HORIZON_NS
        period_ns = self.period_ns
        k, k_end = sample_ns // period_ns, until_ns // period_ns
        if k_end <= k:
            return JointState((q1, q2), (w1, w2))
        self.predictions += count
        p = self.params
        len1, len2, _, _, _, _ = sea_geometry(q1, q2, p)
        x = (float(q1), float(q2), float(w1), float(w2), float(len1 - p.l_ref[0] - d1), float(len2 - p.l_ref[1] - d2),
             float(nv1), float(nv2))
        held: tuple[Pair, Pair] | None = None       # the setpoint acting at sample_ns (the newest applied by then)
        due: list[tuple[int, Pair | None, Pair | None]] = []    # those applied in (sample_ns, until_ns), in order
        for e in self.schedule:
            if e[0] <= sample_ns:
                held = (e[1], e[2])
            elif e[0] < until_ns:
                due.append(e)
        due.append((until_ns, None, None))
        call = self._call
        for apply_ns, next_vx, next_s in due:
            k_next = min(apply_ns // period_ns, k_end)
            if k_next > k:
                hv, hs = held if held is not None else ((0.0, 0.0), (0.0, 0.0))
                # the nominal closed loop without the edge's observer (it has no model of the disturbance)
                # plain floats and ints: the types the entry point was made for
                args = (x, int(k), int(k_next - k), period_ns, self.substeps, (float(hv[0]), float(hv[1])),
                        (float(hs[0]), float(hs[1])), held is None, p, self._gains, OBSERVER_UNSTARTED, self.dt_s)
                if call is None:
                    call = self._call = entry(self.kernel, args)
                x = call(*args)
                k = k_next
            if next_vx is not None and next_s is not None:
                held = (next_vx, next_s)
        return JointState((x[0], x[1]), (x[2], x[3]))
