"""The edge's setpoint envelope: a SETPOINT whose spring-deflection setpoint v_x is not finite or exceeds the configured
bound (`[safety.setpoint] deflection_max_m`) is rejected before it reaches the inner loop: counted
(`setpoints_out_of_envelope`), logged, never applied (the edge keeps the previous setpoint; a controller that sends
nothing else lets the setpoint timeout and the driver's watchdog take the limb to its safe state). Pure: values in,
verdict out."""
from __future__ import annotations

import logging
import math
from typing import NamedTuple

from sea_hil.config.safety import SetpointEnvelopeConfig

INF = float("inf")


class Verdict(NamedTuple):
    ok: bool
    reason: str = ""


ACCEPTED = Verdict(True)


class SetpointEnvelope(NamedTuple):
    deflection_max_m: tuple[float, float] = (INF, INF)

    @classmethod
    def from_config(cls, cfg: SetpointEnvelopeConfig) -> SetpointEnvelope:
        """The configured envelope; with `enabled = false` only non-finite setpoints are rejected."""
        return cls(cfg.deflection_max_m if cfg.enabled else (INF, INF))

    def check(self, deflection_m: tuple[float, float]) -> Verdict:
        if admissible(deflection_m, self.deflection_max_m):
            return ACCEPTED
        for j, v in enumerate(deflection_m):
            if not math.isfinite(v):
                return Verdict(False, f"v_x{j + 1} = {v} is not finite")
            if abs(v) > self.deflection_max_m[j]:
                return Verdict(False, f"|v_x{j + 1}| = {abs(v):.6g} m above {self.deflection_max_m[j]:.6g} m")
        return ACCEPTED


def admissible(deflection_m: tuple[float, float], deflection_max_m: tuple[float, float]) -> bool:
    """The envelope's verdict on plain numbers (`SetpointEnvelope.check` says why not; the offline session kernel
    compiles this)."""
    for j in range(2):
        v = deflection_m[j]
        if not math.isfinite(v) or abs(v) > deflection_max_m[j]:
            return False
    return True


class EnvelopeGate:
    """The edge's use of the envelope: `admit` checks one setpoint, counts (`rejected`) and logs a rejection (the
    first ten, then every power of two of the count: a bad stream cannot flood the log)."""

    def __init__(self, envelope: SetpointEnvelope, log: logging.Logger) -> None:
        self.envelope, self.log, self.rejected = envelope, log, 0

    def admit(self, seq: int, deflection_m: tuple[float, float]) -> bool:
        verdict = self.envelope.check(deflection_m)
        if not verdict.ok:
            self.rejected += 1
            n = self.rejected
            if n <= 10 or n & (n - 1) == 0:
                self.log.warning("setpoint seq %d rejected (out of envelope, %d so far): %s", seq, n, verdict.reason)
        return verdict.ok
