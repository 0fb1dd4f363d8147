"""bench/ by purpose: every `bench/bench_*.py` is a figure of BENCHMARKS.md (a step of bench/run_all.py), each step's
script exists, and the one-off studies of bench/studies/ (run by nothing in CI) still import."""
from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from bench import run_all

BENCH = Path(__file__).resolve().parents[1] / "bench"
STUDIES = sorted(p.stem for p in (BENCH / "studies").glob("*.py") if p.stem != "__init__")


def test_every_benchmark_script_is_a_figure_and_every_figure_a_script() -> None:
    steps = {name for name, *_ in run_all.STEPS + run_all.LONG_STEPS}
    scripts = {p.stem for p in BENCH.glob("bench_*.py")}
    assert scripts == steps, f"not run by run_all: {sorted(scripts - steps)}; no script: {sorted(steps - scripts)}"


def test_no_study_is_left_among_the_benchmarks() -> None:
    assert not [p.name for p in BENCH.glob("study_*.py")]
    assert "study_et_acceptance" in STUDIES   # the glob sees the folder


@pytest.mark.parametrize("name", STUDIES)
def test_a_study_imports(name: str) -> None:
    module = importlib.import_module(f"bench.studies.{name}")
    assert module.__doc__, f"bench/studies/{name}.py says what it studies"
