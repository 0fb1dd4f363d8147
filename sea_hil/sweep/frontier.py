"""Comparing event-triggered control with periodic sampling on the traffic-error plane (issue 16): periodic TT at
several sample periods gives a curve of (total link messages, max tracking error); an ET point is judged against
TT's error at the same number of messages, linearly interpolated between the two periods whose totals bracket it.
Pure functions, no I/O (used by `sea-hil sweep`'s sweep.md and bench/studies/study_et_acceptance.py)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from itertools import pairwise

from sea_hil.errors import SeaHilError


class OutsideBaseline(SeaHilError):
    """The messages asked about lie outside the range TT's periods cover (no extrapolation)."""


def tt_error_at(total_msgs: float, tt_points: Sequence[tuple[float, float]]) -> float:
    """TT's max error at `total_msgs` total link messages: `tt_points` are (total messages, max error) of TT at
    different sample periods; linear in messages between the neighbouring points (the mean error where several
    points share a message count). Raises `OutsideBaseline` outside [fewest, most] messages, ValueError if
    `tt_points` is empty or holds a non-finite value."""
    if not tt_points:
        raise ValueError("tt_error_at: no TT points")
    by_msgs: dict[float, list[float]] = {}
    for msgs, err in tt_points:
        if not (math.isfinite(msgs) and math.isfinite(err)):
            raise ValueError(f"tt_error_at: non-finite TT point ({msgs}, {err})")
        by_msgs.setdefault(float(msgs), []).append(float(err))
    xs = sorted(by_msgs)
    ys = [sum(by_msgs[x]) / len(by_msgs[x]) for x in xs]
    if not xs[0] <= total_msgs <= xs[-1]:
        raise OutsideBaseline(f"{total_msgs:g} messages is outside TT's measured range [{xs[0]:g}, {xs[-1]:g}]")
    if float(total_msgs) in by_msgs:   # at a measured period: its own error, exactly
        return ys[xs.index(float(total_msgs))]
    for (x0, y0), (x1, y1) in pairwise(zip(xs, ys, strict=True)):
        if x0 < total_msgs < x1:
            return y0 + (y1 - y0) * (total_msgs - x0) / (x1 - x0)
    raise AssertionError("unreachable: total_msgs is inside [xs[0], xs[-1]]")


def dominates(et_msgs: float, et_err: float, tt_points: Sequence[tuple[float, float]],
              factor: float = 0.5) -> tuple[bool, float]:
    """(ET's error <= factor x TT's interpolated error at ET's message count, that TT error)."""
    tt_err = tt_error_at(et_msgs, tt_points)
    return et_err <= factor * tt_err, tt_err
