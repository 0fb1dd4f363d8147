"""Opt-in pytest plugin for measuring where the suite's time goes on a shared machine (issue 12): per test, wall
time and CPU time (this process with its threads, and the waited-for child processes), as TSV
`nodeid, wall_s, self_cpu_s, children_cpu_s`. CPU time is far less load-dependent than `--durations`' wall time.

    CPU_DUR_OUT=/tmp/cpu.tsv PYTHONPATH=tests .venv/bin/python -m pytest -p cpu_durations tests

Not loaded by default; under xdist each worker would overwrite the file (use it serially)."""
from __future__ import annotations

import os
import resource
import time
from collections.abc import Generator

import pytest

_ROWS: list[tuple[str, float, float, float]] = []


def _cpu_s() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, None, None]:
    del nextitem
    t0_ns = time.monotonic_ns()
    own0_s, kids0_s = _cpu_s()
    yield
    own1_s, kids1_s = _cpu_s()
    _ROWS.append((item.nodeid, (time.monotonic_ns() - t0_ns) / 1e9, own1_s - own0_s, kids1_s - kids0_s))


def pytest_unconfigure(config: pytest.Config) -> None:
    del config
    out = os.environ.get("CPU_DUR_OUT")
    if out:
        with open(out, "w", encoding="utf-8") as fh:
            fh.writelines(f"{n}\t{w:.3f}\t{s:.3f}\t{c:.3f}\n" for n, w, s, c in _ROWS)
