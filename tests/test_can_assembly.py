"""Feedback assembly (three frames per sample) and rolling time/sequence arithmetic (sea_hil.protocol.can_assembly)."""
from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_assembly import FeedbackAssembler, seq_gap, unwrap_us
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import T_US_MODULUS, EStop, Feedback


@pytest.fixture(scope="module")
def codec() -> SeaCodec:
    return SeaCodec()


def _fb(seq: int, node: int = 1) -> Feedback:
    return Feedback(node, seq, 1000 + seq, (0.5, -0.25), (1.0, -2.0), (0.001, -0.002), (0.1, -0.2))


def test_assembler_pairs_any_order(codec: SeaCodec) -> None:
    for order in itertools.permutations(range(3)):
        asm = FeedbackAssembler()
        parts = [codec.decode(m) for m in codec.encode_feedback(_fb(7))]
        results = [asm.push(parts[i]) for i in order]
        assert results[:2] == [None, None] and results[2] == _fb(7)
        assert (asm.incomplete, asm.stale) == (0, 0)


def test_assembler_drops_incomplete_stale_and_duplicates() -> None:
    asm = FeedbackAssembler(max_pending=2)
    a, d, v = _fb(10).parts()
    assert asm.push(a) is None and asm.push(d) is None         # sample 10 lacks its velocity frame
    assert [asm.push(p) for p in _fb(11).parts()][-1] == _fb(11)
    assert asm.incomplete == 1                                  # 10 dropped once 11 completed
    assert asm.push(v) is None and asm.stale == 1               # late part of the closed sample 10
    assert asm.push(_fb(11).parts()[0]) is None and asm.stale == 2  # repeat of a completed sample
    a12 = _fb(12).parts()[0]
    assert asm.push(a12) is None and asm.push(a12) is None and asm.stale == 3  # duplicate part
    for seq in (13, 14):                                        # > max_pending open samples: oldest evicted
        asm.push(_fb(seq).parts()[0])
    assert asm.incomplete == 2
    assert [asm.push(p) for p in _fb(12, node=2).parts()][-1] == _fb(12, node=2)  # nodes are independent
    with pytest.raises(TypeError):
        asm.push(EStop(1))  # type: ignore[arg-type]


def test_assembler_across_seq_wrap() -> None:
    asm = FeedbackAssembler()
    got = [fb for seq in range(250, 270) for p in _fb(seq % 256).parts() if (fb := asm.push(p))]
    assert [fb.seq for fb in got] == [s % 256 for s in range(250, 270)]
    assert (asm.incomplete, asm.stale) == (0, 0)


@given(full=st.integers(0, 10**12), gap=st.integers(-32768, 32767))
def test_unwrap_us_property(full: int, gap: int) -> None:
    assert unwrap_us(full, (full + gap) % T_US_MODULUS) == full + gap


def test_unwrap_us_examples_and_errors() -> None:
    assert unwrap_us(65_500, 20) == 65_556          # forward across the wrap
    assert unwrap_us(70_000, 69_995 - 65_536) == 69_995  # a slightly older sample
    assert unwrap_us(0, 1000) == 1000
    for bad in (-1, 65_536, 1.5):
        with pytest.raises(MalformedFrame):
            unwrap_us(0, bad)  # type: ignore[arg-type]
    assert (seq_gap(255, 0), seq_gap(3, 3), seq_gap(10, 5)) == (1, 0, 251)
