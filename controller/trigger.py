"""Event trigger, paper Eq. 16-19 plus the ||X~|| > r rule of Sec. 4 and a maximum inter-event time.

epsilon = [X~, X_d] (Eq. 11) is stacked as an 8-vector (x~1, x~2, x_d, xdot_d for both joints); the event error is
e = epsilon(t_i) - epsilon(t) (Eq. 16) and an event fires when ||e|| >= eta / (L sqrt(1 + c^2)) (violation of Eq. 19),
when ||X~|| > r, or when max_inter_event_s has passed since the last event (keeps the link and watchdog alive).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sea_hil.protocol.payloads import TriggerReason


def error_threshold(eta: float, lipschitz_l: float, c: float) -> float:
    """Right-hand side of Eq. 19."""
    return eta / (lipschitz_l * math.sqrt(1.0 + c * c))


def epsilon(xt: tuple[float, float, float, float], xd: tuple[float, float], xd_dot: tuple[float, float]
            ) -> tuple[float, ...]:
    return (xt[0], xt[1], xt[2], xt[3], xd[0], xd[1], xd_dot[0], xd_dot[1])


def _distance(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Euclidean distance, summed left to right (the hot path of `EventTrigger.update`)."""
    acc = 0.0
    for u, v in zip(a, b):  # noqa: B905 - numba compiles this (its zip takes no strict=); a, b: 8 floats each
        d = u - v
        acc += d * d
    return math.sqrt(acc)


NO_EVENT = -1
"""`event_reason` when no event fires (else a `TriggerReason` value)."""
_EPS_UNSET = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_INITIAL, _ERROR_BOUND = int(TriggerReason.INITIAL), int(TriggerReason.ERROR_BOUND)
_TRACKING_BOUND, _HEARTBEAT = int(TriggerReason.TRACKING_BOUND), int(TriggerReason.HEARTBEAT)


def event_reason(started: bool, eps_i: tuple[float, ...], t_i_ns: int, t_ns: int, eps: tuple[float, ...],
                 threshold: float, r: float, max_inter_event_ns: int) -> int:
    """The trigger rule on plain numbers: the `TriggerReason` value of the event at (t_ns, eps) after the last event
    (t_i_ns, eps_i), or NO_EVENT; `started` False: no event yet (INITIAL). Plain float code: `EventTrigger.update`
    runs it."""
    if not started:
        return _INITIAL
    e_norm = _distance(eps_i, eps)
    x_norm = math.sqrt(eps[0] * eps[0] + eps[1] * eps[1] + eps[2] * eps[2] + eps[3] * eps[3])  # inf, no raise
    if e_norm >= threshold:
        return _ERROR_BOUND
    if x_norm > r:
        return _TRACKING_BOUND
    if t_ns - t_i_ns >= max_inter_event_ns:
        return _HEARTBEAT
    return NO_EVENT


@dataclass
class EventTrigger:
    """Stateful trigger; `update` is called once per outer sample and says whether to transmit."""
    threshold: float
    r: float
    max_inter_event_ns: int
    _eps_i: tuple[float, ...] | None = None
    _t_i_ns: int = 0

    def update(self, t_ns: int, eps: tuple[float, ...]) -> TriggerReason | None:
        started = self._eps_i is not None
        code = event_reason(started, self._eps_i if self._eps_i is not None else _EPS_UNSET, self._t_i_ns, t_ns, eps,
                            self.threshold, self.r, self.max_inter_event_ns)
        if code == NO_EVENT:
            return None
        self._eps_i = eps
        self._t_i_ns = t_ns
        return TriggerReason(code)

    def reset(self) -> None:
        """Forget the last event: the next `update` is INITIAL (a new trajectory anchor at the edge)."""
        self._eps_i, self._t_i_ns = None, 0


@dataclass
class TimeTrigger:
    """Time-triggered baseline: every sample is an event."""

    def update(self, t_ns: int, eps: tuple[float, ...]) -> TriggerReason:
        return TriggerReason.TIME

    def reset(self) -> None:
        """Nothing to forget."""
