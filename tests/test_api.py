"""The public API and the pytest plugin: the documented surface is the package's (docs/api.md), a user's test that
uses only the plugin's fixtures and the public API passes (the docs' own example, run with pytester), and the
fixtures end everything they started even when the user's test fails."""
from __future__ import annotations

import dataclasses
import importlib
import os
import re
import sys
import threading
from pathlib import Path

import pytest

import sea_hil

DOCS = Path(__file__).resolve().parents[1] / "docs" / "api.md"
NODE_THREADS = {"plant", "edge", "controller", "recorder", "rec-zenoh", "rec-can", "rec-taps", "sea-hil-session"}
SHORT = '''
import pytest
import sea_hil


@pytest.fixture
def sea_config():
    return sea_hil.load_config(overrides={"trajectory": {"lead_in_s": 0.2}})   # the default gait, a short lead-in
'''


def documented_surface() -> dict[str, set[str] | None]:
    """name -> documented members (None: no member list) from the public-surface block of docs/api.md."""
    text = DOCS.read_text(encoding="utf-8")
    block = re.search(r"<!-- public-surface.*?-->\n```\n(.*?)```\n<!-- /public-surface -->", text, re.S)
    assert block, "docs/api.md has no public-surface block"
    out: dict[str, set[str] | None] = {}
    for line in block.group(1).strip().splitlines():
        name, _, members = line.partition(":")
        members = members.strip()
        out[name.strip()] = None if not members or members.startswith("(") else {
            m.strip() for m in members.split(",")}
    return out


def _public(obj: object) -> set[str]:
    return {n for n in dir(obj) if not n.startswith("_")}


def test_public_surface_is_the_documented_one(tmp_path):
    doc = documented_surface()
    assert set(sea_hil.__all__) == set(doc)
    assert isinstance(sea_hil.__version__, str) and sea_hil.__version__
    assert {f.name for f in dataclasses.fields(sea_hil.DriveSnapshot)} == doc["DriveSnapshot"]
    with sea_hil.EmulatedDriver(f"virtual:api-{os.getpid()}", lockstep=True) as driver:
        assert _public(driver) == doc["EmulatedDriver"]
    session = sea_hil.Session(out=tmp_path)
    try:
        assert _public(session) == doc["Session"]
    finally:
        session.close()
    with pytest.raises(AttributeError):
        _ = sea_hil.not_public


def test_driver_snapshot_and_counters_and_bad_input():
    with sea_hil.EmulatedDriver(f"virtual:api-snap-{os.getpid()}", [1, 2]) as driver:
        snap = driver.snapshot(2)
        assert snap.node_id == 2 and snap.state == "INIT" and len(snap.theta_rad) == 2
        assert {"ticks", "node1_commands", "node2_watchdog_trips"} <= set(driver.counters)
        with pytest.raises(sea_hil.SeaHilError, match="no emulated drive with node id 3"):
            driver.snapshot(3)
    assert not driver.running
    driver.close()   # idempotent
    with pytest.raises(sea_hil.SeaHilError):
        sea_hil.Session(controller="pid")


# imported by numba's lowering on the first compile in a process (numba/core/pythonapi.py, lowering.py, base.py)
LOWERING_MODULES = ("numba.core.boxing", "numba.core.unsafe.eh", "numba.core.runtime.context")


@pytest.fixture(autouse=True, scope="module")
def _numba_registries_loaded() -> None:
    """Load numba's lazily imported typing registries before any `pytester` exists. pytester snapshots `sys.modules`
    when it is set up and restores it at teardown: modules numba first imported in between (inside the in-process
    run, e.g. numba.np.polynomial.polynomial_core, whose types register once per process) would be dropped while
    their registrations stay, and the next numba cache load in this process fails with "duplicate registration".
    The serial run had loaded them in an earlier file; under pytest-xdist this file can come first in a worker (41
    failures after it). Autouse fixtures are set up before the test's other fixtures, so before pytester.
    Lowering imports three more modules on a process's first compile (not on a cache load): `numba.core.boxing`
    registers the box/unbox functions, so a compile inside the window (a fresh clone's first compile of a kernel the
    other xdist worker had already cached) dropped it and the next compile failed with "duplicate registration for
    Boolean" (3 failures in a fresh-clone CI run, 2026-12-02). They are imported here too."""
    try:
        from numba.core.registry import cpu_target
    except ImportError:      # numba is optional: without it nothing registers
        return
    cpu_target.target_context.refresh()
    for name in LOWERING_MODULES:
        importlib.import_module(name)


def test_a_compile_after_the_warm_up_imports_no_numba_module() -> None:
    """What pytester's sys.modules restore would drop: after the warm-up fixture a first compile (bool, float, int
    and array arguments, a tuple back; no cache) imports no numba module."""
    numba = pytest.importorskip("numba")
    import numpy as np
    before = set(sys.modules)
    numba.njit(cache=False)(lambda b, x, n, a: (not b, x + a[n]))(True, 1.0, 0, np.zeros(2))
    assert [m for m in sys.modules if m not in before and m.startswith("numba")] == []


def _docs_example() -> str:
    text = DOCS.read_text(encoding="utf-8")
    return re.search(r"```python\n(.*?)```", text, re.S).group(1)


def _alive_node_threads() -> set[str]:
    return {t.name for t in threading.enumerate() if t.name in NODE_THREADS and t.is_alive()}


def _children() -> list[int]:
    me, out = str(os.getpid()), []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[1] == me and fields[0] != "Z":
                out.append(int(entry.name))
    return out


@pytest.mark.slow
def test_a_users_test_passes_with_the_plugin_alone(pytester):
    pytester.makeconftest(SHORT)
    pytester.makepyfile(test_user=_docs_example())
    before = set(_children())   # e.g. the with-vcan guest run in the background (tests/uml_suite.py)
    result = pytester.runpytest_inprocess("-q", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)
    assert not _alive_node_threads() and not set(_children()) - before


@pytest.mark.slow
def test_fixtures_tear_everything_down_when_the_users_test_fails(pytester):
    pytester.makeconftest(SHORT)
    pytester.makepyfile(test_user='''
def test_fails_midway(sea_driver, sea_bus, sea_session):
    session = sea_session(controller="et", cycles=1, lockstep=True)
    assert session.wait_until_running(120)
    assert sea_driver.running
    raise AssertionError("the user's test fails here")


def test_vcan_marker_skips_without_vcan(sea_can_channel):
    pass
''')
    pytester.makeini("[pytest]\nmarkers =\n")
    before = set(_children())
    result = pytester.runpytest_inprocess("-q", "-p", "no:cacheprovider")
    result.assert_outcomes(failed=1, passed=1)
    assert not _alive_node_threads(), _alive_node_threads()
    assert not set(_children()) - before, set(_children()) - before
