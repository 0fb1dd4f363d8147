"""Test-suite set-up: pytest's own `pytester` (tests/test_api.py runs a user's test with the sea-hil plugin), and
the with-vcan guest's socketcan suite started in the background as soon as its host test is collected
(tests/uml_suite.py), so it overlaps the rest of the run; it is ended when pytest ends."""
from __future__ import annotations

import pytest
from uml_suite import BACKGROUND_KEY, SUITE_ARGS, SUITE_TEST, BackgroundRun, can_boot

pytest_plugins = ["pytester"]


def pytest_collection_finish(session: pytest.Session) -> None:
    if session.config.option.collectonly or not any(item.nodeid == SUITE_TEST for item in session.items):
        return
    if can_boot():
        session.config.stash[BACKGROUND_KEY] = BackgroundRun(*SUITE_ARGS)


def pytest_unconfigure(config: pytest.Config) -> None:
    background = config.stash.get(BACKGROUND_KEY, None)
    if background is not None:
        background.stop()
