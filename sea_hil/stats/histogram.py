"""`LogHistogram`: a fixed-size logarithmic histogram for latencies and inter-event times.

Buckets grow geometrically by a factor ``g = 1 + precision`` from ``lowest`` to ``highest``; bucket ``i`` covers
``[lowest*g**i, lowest*g**(i+1))`` and reports its geometric centre, so any reported percentile is within
``sqrt(g) - 1`` (about 0.5 % for ``precision=0.01``) of a sample in the same bucket. Values below ``lowest``
(including 0) fall into an underflow bucket, values above ``highest`` into an overflow bucket; ``min``/``max`` are
exact and clamp every reported percentile. Memory is fixed by the layout (1853 counters for the default
1 us .. 100 s at 1 %), never by the number of samples. Values are unit-agnostic; by convention seconds.
"""
from __future__ import annotations

import math

from sea_hil.errors import MalformedPayload


class LogHistogram:
    """Log-bucketed histogram with exact count/min/max/mean; non-finite or negative values are rejected."""

    def __init__(self, lowest: float = 1e-6, highest: float = 100.0, precision: float = 0.01) -> None:
        if not (0 < lowest < highest and math.isfinite(highest) and 0 < precision < 1):
            raise ValueError(f"bad histogram layout lowest={lowest} highest={highest} precision={precision}")
        self.lowest, self.highest, self.precision = float(lowest), float(highest), float(precision)
        self._log_g = math.log1p(precision)
        self._n_log = int(math.ceil(math.log(highest / lowest) / self._log_g))
        # index 0 = underflow, 1.._n_log = log buckets, _n_log+1 = overflow
        self._counts = [0] * (self._n_log + 2)
        self.count = 0
        self.rejected = 0
        self.sum = 0.0
        self.min = math.inf
        self.max = -math.inf

    # -- recording -------------------------------------------------------------------------------------------
    def _index(self, value: float) -> int:
        if value < self.lowest:
            return 0
        if value >= self.highest:
            return self._n_log + 1
        return min(int(math.log(value / self.lowest) / self._log_g), self._n_log - 1) + 1

    def record(self, value: float, count: int = 1) -> bool:
        """Add `count` samples of `value`; returns False (and counts `rejected`) for NaN/inf/negative values."""
        if not 0 <= value < math.inf or count <= 0:   # NaN, inf and negative values fail the comparison
            self.rejected += 1
            return False
        self._counts[self._index(value)] += count
        self.count += count
        self.sum += value * count
        if value < self.min:   # = min(self.min, value) / max(...) without two builtin calls per sample
            self.min = value
        if value > self.max:
            self.max = value
        return True

    def merge(self, other: LogHistogram) -> None:
        """Add all samples of `other` (same layout required) into this histogram."""
        if (other.lowest, other.highest, other.precision) != (self.lowest, self.highest, self.precision):
            raise MalformedPayload("cannot merge histograms with different layouts")
        for i, c in enumerate(other._counts):
            if c:
                self._counts[i] += c
        self.count += other.count
        self.rejected += other.rejected
        self.sum += other.sum
        self.min = min(self.min, other.min)
        self.max = max(self.max, other.max)

    # -- queries ---------------------------------------------------------------------------------------------
    @property
    def mean(self) -> float:
        return self.sum / self.count if self.count else math.nan

    def _value_of(self, index: int) -> float:
        if index == 0:
            return self.min
        if index == self._n_log + 1:
            return self.max
        return self.lowest * math.exp((index - 0.5) * self._log_g)

    def percentile(self, p: float) -> float:
        """Value at percentile `p` in [0, 100] (rank = ceil(p/100*count), like numpy's "inverted_cdf");
        NaN when empty."""
        if not 0 <= p <= 100:
            raise ValueError(f"percentile must be in [0, 100], got {p}")
        if self.count == 0:
            return math.nan
        rank = max(1, math.ceil(p / 100.0 * self.count))
        seen = 0
        for i, c in enumerate(self._counts):
            seen += c
            if seen >= rank:
                return min(max(self._value_of(i), self.min), self.max)
        return self.max

    def to_dict(self) -> dict[str, float | int | None]:
        """Summary: count, min, mean, p50, p90, p99, p999, max (NaN-free: empty fields are None)."""
        def num(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {"count": self.count, "min": num(self.min), "mean": num(self.mean),
                "p50": num(self.percentile(50)), "p90": num(self.percentile(90)),
                "p99": num(self.percentile(99)), "p999": num(self.percentile(99.9)), "max": num(self.max)}
