"""The fuzz files pass (tests/cpu_suite.py): in the background run tests/conftest.py started, when it did; else,
when they were not collected in this process, in a pytest child here; else they ran in-process and this is skipped."""
from __future__ import annotations

from pathlib import Path

import pytest
from cpu_suite import CPU_RUN_KEY, cpu_run, moved


def test_the_fuzz_files_pass_in_the_background(request: pytest.FixtureRequest, tmp_path: Path) -> None:
    background = request.config.stash.get(CPU_RUN_KEY, None)
    if background is None:
        if any(moved(item.nodeid) for item in request.session.items):
            pytest.skip("the fuzz files run in this process (xdist, or collected without the background run)")
        run = cpu_run(tmp_path)
        try:
            status, output = run.result()
        finally:
            run.stop()
    else:
        status, output = background.result()
    assert status == 0, f"the fuzz files (status {status}):\n{output[-6000:]}"
    assert " passed" in output and " failed" not in output, output[-3000:]
    print(output.strip().splitlines()[-1])
