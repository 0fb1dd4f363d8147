"""Loading a `SeaHilConfig`: embedded default TOML, a user file, overrides; and back to TOML."""
from __future__ import annotations

import copy
import functools
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from sea_hil.config.legacy import migrate_layer
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, val in over.items():
        if isinstance(val, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], val)
        else:
            out[key] = val
    return out


def default_toml_text() -> str:
    return resources.files("sea_hil.config").joinpath("default_config.toml").read_text(encoding="utf-8")


@functools.lru_cache(maxsize=1)
def _default_data() -> dict[str, Any]:
    """The embedded defaults, parsed once per process (a sweep loads a config per grid point)."""
    return tomllib.loads(default_toml_text())


def validation_line(err: ValidationError, prefix: str = "") -> str:
    """A pydantic error on one line: every failing key (`prefix` + its location) and why."""
    parts = []
    for e in err.errors():
        loc = prefix + ".".join(str(p) for p in e["loc"])
        parts.append(f"{loc}: {e['msg']}")
    return "; ".join(parts)


def config_from_dict(data: dict[str, Any]) -> SeaHilConfig:
    try:
        return SeaHilConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(f"invalid config: {validation_line(err)}") from err


def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None) -> SeaHilConfig:
    """Embedded defaults, overlaid with the TOML file at `path` (if any), then `overrides` (nested dict). Keys of
    older files are moved to their one source or dropped, with a warning (sea_hil/config/legacy.py)."""
    data = copy.deepcopy(_default_data())
    if path is not None:
        p = Path(path)
        try:
            user = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError as err:
            raise ConfigError(f"config file not found: {p}") from err
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"config file {p} is not valid TOML: {err}") from err
        except (OSError, UnicodeDecodeError) as err:
            raise ConfigError(f"cannot read config file {p}: {err}") from err
        data = _merge(data, migrate_layer(user, f"config file {p}"))
    if overrides:
        data = _merge(data, migrate_layer(overrides, "config overrides"))
    return config_from_dict(data)


def config_to_toml(cfg: SeaHilConfig) -> str:
    """Serialise a config back to TOML (used to attach the effective config to recordings)."""
    lines: list[str] = []

    def fmt(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return repr(v)

    def emit(prefix: str, d: dict[str, Any]) -> None:
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict) and v is not None}  # None = unset
        tables = {k: v for k, v in d.items() if isinstance(v, dict)}
        if scalars:
            lines.append(f"[{prefix}]")
            lines.extend(f"{k} = {fmt(v)}" for k, v in scalars.items())
            lines.append("")
        for k, v in tables.items():
            emit(f"{prefix}.{k}" if prefix else k, v)

    d = cfg.model_dump(mode="python")
    arrays = {k: d.pop(k) for k in [k for k, v in d.items() if isinstance(v, (list, tuple))]}  # [[limbs]]
    emit("", d)
    for k, items in arrays.items():
        for item in items:
            lines.append(f"[[{k}]]")
            lines.extend(f"{ik} = {fmt(iv)}" for ik, iv in item.items())
            lines.append("")
    return "\n".join(lines)
