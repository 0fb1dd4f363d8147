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
    for u, v in zip(a, b):
        d = u - v
        acc += d * d
    return math.sqrt(acc)


@dataclass
class EventTrigger:
    """Stateful trigger; `update` is called once per outer sample and says whether to transmit."""
    threshold: float
    r: float
    max_inter_event_ns: int
    _eps_i: tuple[float, ...] | None = None
    _t_i_ns: int = 0

    def update(self, t_ns: int, eps: tuple[float, ...]) -> TriggerReason | None:
        if self._eps_i is None:
            reason: TriggerReason | None = TriggerReason.INITIAL
        else:
            e_norm = _distance(self._eps_i, eps)
            x_norm = math.sqrt(eps[0] * eps[0] + eps[1] * eps[1] + eps[2] * eps[2] + eps[3] * eps[3])  # inf, no raise
            if e_norm >= self.threshold:
                reason = TriggerReason.ERROR_BOUND
            elif x_norm > self.r:
                reason = TriggerReason.TRACKING_BOUND
            elif t_ns - self._t_i_ns >= self.max_inter_event_ns:
                reason = TriggerReason.HEARTBEAT
            else:
                reason = None
        if reason is not None:
            self._eps_i = eps
            self._t_i_ns = t_ns
        return reason


@dataclass
class TimeTrigger:
    """Time-triggered baseline: every sample is an event."""

    def update(self, t_ns: int, eps: tuple[float, ...]) -> TriggerReason:
        return TriggerReason.TIME
