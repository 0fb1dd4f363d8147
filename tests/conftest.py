"""Test-suite set-up: pytest's own `pytester` (tests/test_api.py runs a user's test with the sea-hil plugin)."""
pytest_plugins = ["pytester"]
