"""The wheel installs one top-level import package, `sea_hil` (the user's folders `protocol/`, `controller/`,
`plant_emulator/` inside it), with the DBC and the default TOML, and every module of the source tree.

Built from a copy of the sources (so no build/ or egg-info lands in the checkout, and no stale build/lib file can
slip into the wheel) with `pip wheel --no-deps --no-build-isolation` (offline, a few seconds; needs the dev extra's
setuptools >= 70.1, which builds wheels without the `wheel` package)."""
from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# source folder -> the package it is installed as (pyproject.toml [tool.setuptools.package-dir])
SOURCES = {"sea_hil": "sea_hil", "protocol": "sea_hil/protocol", "controller": "sea_hil/controller",
           "plant_emulator": "sea_hil/plant_emulator"}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    for folder in SOURCES:
        shutil.copytree(REPO / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    out = tmp / "dist"
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
                           "-q", "-w", str(out), str(src)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    (path,) = out.glob("sea_hil-*.whl")
    with zipfile.ZipFile(path) as zf:
        yield zf


def test_the_only_top_level_package_is_sea_hil(wheel: zipfile.ZipFile) -> None:
    names = wheel.namelist()
    (top_level,) = [n for n in names if n.endswith(".dist-info/top_level.txt")]
    assert wheel.read(top_level).decode().split() == ["sea_hil"]
    assert {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")} == {"sea_hil"}
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "sea-hil = sea_hil.cli:main" in wheel.read(entry_points).decode()


def test_data_files_and_every_module_are_inside(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    assert {"sea_hil/protocol/sea.dbc", "sea_hil/config/default_config.toml",
            "sea_hil/ros2/sea_hil_msgs/msg/LimbState.msg", "sea_hil/ros2/sea_hil_msgs/msg/Setpoint.msg",
            "sea_hil/py.typed"} <= names
    expected = {f"{pkg}/{p.relative_to(REPO / folder).as_posix()}"
                for folder, pkg in SOURCES.items() for p in (REPO / folder).rglob("*.py")
                if "__pycache__" not in p.parts}
    assert expected - names == set()      # a package missing from pyproject.toml's list would drop its modules
