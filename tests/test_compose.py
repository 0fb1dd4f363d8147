"""docker-compose.yml cannot run here (no Docker engine); check that it parses and every command is a real
`sea-hil` invocation that the CLI accepts and whose `--help` works."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml

from sea_hil.cli import build_parser
from sea_hil.config.loader import load_config

ROOT = Path(__file__).resolve().parents[1]


def _compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def test_compose_has_the_services():
    services = _compose()["services"]
    assert {"zenoh-router", "plant", "edge", "controller", "recorder"} <= set(services)
    assert services["zenoh-router"]["image"].startswith("eclipse/zenoh")
    assert services["plant"]["network_mode"] == "host"


def test_every_command_parses_and_has_help():
    parser = build_parser()
    for name, svc in _compose()["services"].items():
        cmd = svc.get("command", [])
        if not cmd or cmd[0] != "sea-hil":
            continue
        args = parser.parse_args(cmd[1:])
        assert args.command == cmd[1], name
        out = subprocess.run([sys.executable, "-m", "sea_hil.cli", cmd[1], "--help"], capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 0 and "usage: sea-hil" in out.stdout, name


def test_shared_config_volume_file_loads():
    volumes = _compose()["services"]["controller"]["volumes"]
    assert any(v.endswith(":/config:ro") for v in volumes)
    cfg = load_config(ROOT / "configs" / "session.toml")
    assert cfg.zenoh.mode == "client"


def test_router_image_is_the_zenoh_release_the_package_requires():
    """The zenohd image and the Python package speak the same release: pyproject.toml's eclipse-zenoh requirement
    admits the image's tag and nothing of the next minor series (the installed package satisfies it: pip)."""
    import tomllib

    from packaging.requirements import Requirement

    tag = _compose()["services"]["zenoh-router"]["image"].split(":")[1]
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    spec = next(Requirement(d).specifier for d in deps if Requirement(d).name == "eclipse-zenoh")
    major, minor, _ = tag.split(".")
    assert tag in spec and f"{major}.{int(minor) + 1}.0" not in spec
