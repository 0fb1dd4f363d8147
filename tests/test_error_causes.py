"""Errors that wrap another keep it as their cause (`raise ... from err`), so `-vv` logs and tracebacks show what
failed underneath the one-line message."""
from __future__ import annotations

import struct
import tomllib
from pathlib import Path

import pydantic
import pytest

from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError, MalformedPayload, RecordingError
from sea_hil.protocol.link import parse_link_spec
from sea_hil.protocol.payloads import MAGIC, VERSION, decode
from sea_hil.recorder.reader import read_session
from sea_hil.sweep.grid import parse_axis


def _cause(fn, *args) -> BaseException | None:
    with pytest.raises((ConfigError, MalformedPayload, RecordingError)) as info:
        fn(*args)
    return info.value.__cause__


def test_wrapped_errors_keep_their_cause(tmp_path: Path) -> None:
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("[plant\n", encoding="utf-8")
    assert isinstance(_cause(load_config, bad_toml), tomllib.TOMLDecodeError)
    assert isinstance(_cause(load_config, tmp_path / "absent.toml"), FileNotFoundError)
    assert isinstance(_cause(load_config, None, {"plant": {"m1_kg": -1.0}}), pydantic.ValidationError)
    assert isinstance(_cause(parse_link_spec, "delay=abcms"), ValueError)
    assert isinstance(_cause(parse_axis, "eta", "x"), ValueError)
    assert isinstance(_cause(decode, struct.pack("<2sBBIQQ", MAGIC, VERSION, 99, 1, 1, 7)), ValueError)
    assert isinstance(_cause(read_session, tmp_path), OSError)      # a directory
