"""Session epochs: every sender of binary Zenoh payloads picks a random 64-bit epoch when it starts and stamps it in
every payload header (`protocol/payloads.toml`, `epoch`); a receiver learns a peer's epoch on first contact.

`PeerEpoch.check` is the one place a receiver decides about a payload's epoch (the edge's setpoint intake and the
remote controller's state intake call it before their sequence tracking):

- the peer's current epoch (or the first one seen): `CURRENT`, go on with the sequence number;
- a new epoch while a restart is plausible (the intake's restart condition: the old stream has timed out and the
  seq is that of a fresh sender): `RESTART`, the old epoch is retired, handled as the intake's restart path;
- a retired epoch (the peer before its restart): `REJECTED`, counted as `old`;
- any other new epoch (the stream is alive, or the seq is not a fresh sender's): `REJECTED`, counted as `foreign`
  -- bytes recorded in an earlier session and re-published, or a second sender on the same key.

The epoch comes from the OS's CSPRNG (`secrets`), never from the session seed: it must differ across restarts, and
it reaches no deterministic field (it is not in any stats record or summary), so lockstep results stay bit for bit
reproducible. Rejections are logged at 1, 10, 100, ... (not a flood). See docs/reliability.md.
"""
from __future__ import annotations

import logging
import secrets
from collections import deque
from collections.abc import Callable
from enum import IntEnum

RETIRED_KEPT = 64        # retired epochs remembered per peer (one per restart)


def new_epoch() -> int:
    """A random, non-zero 64-bit session epoch."""
    epoch = 0
    while epoch == 0:
        epoch = secrets.randbits(64)
    return epoch


class EpochVerdict(IntEnum):
    CURRENT = 0    # the peer's known epoch (learned on first contact)
    RESTART = 1    # a new epoch accepted as the peer's restart
    REJECTED = 2   # an old or foreign epoch: drop the payload (counted)


class PeerEpoch:
    """The epoch of one peer's payload stream, as its receiver knows it (`peer`: a name for the log)."""

    def __init__(self, peer: str, log: logging.Logger) -> None:
        self.peer, self.log = peer, log
        self.current: int | None = None
        self.retired: deque[int] = deque(maxlen=RETIRED_KEPT)
        self.restarts = self.old = self.foreign = 0

    def check(self, epoch: int, restart_ok: Callable[[], bool]) -> EpochVerdict:
        """The verdict on a payload of `epoch`; `restart_ok()` (asked only for a new epoch) says whether the
        intake's restart condition holds."""
        if self.current is None:
            self.current = epoch
            self.log.info("%s epoch %016x learned", self.peer, epoch)
            return EpochVerdict.CURRENT
        if epoch == self.current:
            return EpochVerdict.CURRENT
        if epoch in self.retired:
            self.old += 1
            self._log_rejection("old", self.old, epoch)
            return EpochVerdict.REJECTED
        if not restart_ok():
            self.foreign += 1
            self._log_rejection("foreign", self.foreign, epoch)
            return EpochVerdict.REJECTED
        self.retired.append(self.current)
        self.log.warning("%s restarted: epoch %016x -> %016x", self.peer, self.current, epoch)
        self.current = epoch
        self.restarts += 1
        return EpochVerdict.RESTART

    def _log_rejection(self, kind: str, count: int, epoch: int) -> None:
        if _is_power_of_ten(count):
            self.log.warning("%s: payload of %s epoch %016x rejected (current %016x; %d so far)", self.peer, kind,
                             epoch, self.current or 0, count)

    def as_dict(self) -> dict[str, int]:
        return {"epoch_old": self.old, "epoch_foreign": self.foreign}


def _is_power_of_ten(n: int) -> bool:
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1
