"""Statistics: histogram precision vs numpy, merge/serialise; the CAN frame length formula."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sea_hil.errors import MalformedFrame, MalformedPayload
from sea_hil.stats.can_bits import can_frame_bits
from sea_hil.stats.histogram import LogHistogram

S = 1_000_000_000
PCTS = (1, 10, 25, 50, 75, 90, 99, 99.9, 100)


def _filled(values: np.ndarray) -> LogHistogram:
    h = LogHistogram()
    for v in values:
        assert h.record(float(v))
    return h


def test_histogram_percentiles_match_numpy_within_precision() -> None:
    rng = np.random.default_rng(1)
    data = rng.lognormal(mean=math.log(0.01), sigma=2.0, size=20_000).clip(2e-6, 50.0)
    h = _filled(data)
    assert h.count == data.size
    assert h.min == data.min() and h.max == data.max()
    assert h.mean == pytest.approx(data.mean(), rel=1e-9)
    for p in PCTS:
        assert h.percentile(p) == pytest.approx(np.percentile(data, p, method="inverted_cdf"), rel=0.01), p


def test_histogram_is_fixed_size_and_handles_edges() -> None:
    h = LogHistogram()
    n_buckets = len(h._counts)
    for v in (0.0, 1e-9, 1e3, 5.0):
        h.record(v)
    assert not h.record(math.nan) and not h.record(-1.0) and not h.record(math.inf)
    assert h.rejected == 3 and h.count == 4 and len(h._counts) == n_buckets
    assert h.percentile(0) == 0.0 and h.percentile(100) == 1e3
    assert math.isnan(LogHistogram().percentile(50))
    assert LogHistogram().to_dict()["p50"] is None
    with pytest.raises(ValueError):
        h.percentile(101)


def test_histogram_merge_equals_histogram_of_union() -> None:
    rng = np.random.default_rng(2)
    a, b = rng.exponential(0.05, 3000), rng.exponential(2.0, 1000)
    ha, hb, hab = _filled(a), _filled(b), _filled(np.concatenate([a, b]))
    ha.merge(hb)
    assert ha.count == hab.count and ha._counts == hab._counts
    assert ha.to_dict() == pytest.approx(hab.to_dict())
    with pytest.raises(MalformedPayload):
        ha.merge(LogHistogram(precision=0.02))


def test_can_frame_bits_formula() -> None:
    # hand-computed: std 8 bytes -> 64 data + 47 fixed (incl. 3 IFS) + floor(97/4)=24 stuff = 135
    assert can_frame_bits(8) == 135
    assert can_frame_bits(0) == 47 + 33 // 4 == 55
    assert can_frame_bits(8, extended=True) == 64 + 67 + 117 // 4 == 160
    assert can_frame_bits(15) == can_frame_bits(8)
    assert can_frame_bits(8, worst_case=False) == 111 and can_frame_bits(8, True, worst_case=False) == 131
    with pytest.raises(MalformedFrame):
        can_frame_bits(16)


