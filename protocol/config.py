"""Frozen configuration objects loaded from TOML.

One `SeaHilConfig` is built per process from the embedded default (`protocol/default_config.toml`) overlaid with
an optional user file; unknown keys and wrong types are errors (`ConfigError`, one line). Nothing here is global:
callers pass the config object down.
"""
from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from protocol.errors import ConfigError


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=False)


Pair = tuple[float, float]


class PlantConfig(_Frozen):
    """Physical parameters of the limb (paper Fig. 1 and Sec. 4) and of the SEAs (Eq. 6)."""
    d_m: tuple[float, float, float, float, float, float, float, float, float, float] = Field(
        description="d1..d10 of Fig. 1 in metres")
    r1_m: float
    r2_m: float
    l1_m: float
    l2_m: float
    m1_kg: float = Field(gt=0)
    m2_kg: float = Field(gt=0)
    i1_kgm2: float = Field(ge=0)
    i2_kgm2: float = Field(ge=0)
    k1_n_per_m: float = Field(gt=0)
    k2_n_per_m: float = Field(gt=0)
    b1_nms: float = Field(ge=0)
    b2_nms: float = Field(ge=0)
    g_m_s2: float = 9.81
    alpha1_rad: float
    alpha2_rad: float
    theta_ref_rad: Pair = (0.0, 0.0)
    initial_theta_rad: Pair = Field((0.05, 0.2831), description="joint angles the driver boots at (rest, holding)")
    nut_damping_per_s: float = Field(48.0, ge=0)
    voltage_limit_v: float = Field(24.0, gt=0)
    include_i2_in_coupling: bool = True


class DisturbanceConfig(_Frozen):
    kind: Literal["none", "constant", "sine", "noise"] = "none"
    amplitude_nm: Pair = (0.0, 0.0)
    frequency_hz: float = Field(0.5, ge=0)
    noise_hold_s: float = Field(0.01, gt=0)
    seed: int = 0


class TrajectoryConfig(_Frozen):
    kind: Literal["gait", "csv"] = "gait"
    period_s: float = Field(10.0, gt=0)
    csv_path: str = ""
    lead_in_s: float = Field(0.5, ge=0, description="networked session: quintic from the measured start state onto "
                             "the trajectory before the measured cycles; 0 = start the cycles at once")


class ControllerConfig(_Frozen):
    c: float = Field(gt=0)
    rho: float = Field(ge=0)
    kp1: float = Field(gt=0)
    kp2: float = Field(gt=0)
    boundary_layer: float = Field(0.0, ge=0, description="0 = sign(s) as in the paper; >0 = sat(s/phi)")
    sample_period_s: float = Field(0.01, gt=0)
    inner_rate_hz: float = Field(1000.0, gt=0)
    cross_term_scale: Literal["normalized", "paper", "off"] = "normalized"
    cross_term_bandwidth_rad_s: float = Field(30.0, gt=0, description="omega_c of the normalized Eq. 27 cross term")


class TriggerConfig(_Frozen):
    r: float = Field(gt=0)
    eta: float = Field(gt=0)
    lipschitz_l: float = Field(gt=0)
    max_inter_event_s: float = Field(0.25, gt=0)


class SimConfig(_Frozen):
    substeps: int = Field(2, ge=1)
    cycles: int = Field(1, ge=1)


class CanConfig(_Frozen):
    interface: str = "virtual:sea-hil"
    bitrate_bps: int = Field(1_000_000, gt=0)
    node_ids: tuple[int, ...] = (1,)
    feedback_rate_hz: float = Field(1000.0, gt=0)
    heartbeat_rate_hz: float = Field(10.0, gt=0)
    watchdog_timeout_s: float = Field(0.1, gt=0)
    send_retries: int = Field(5, ge=0)
    send_backoff_s: float = Field(0.0002, ge=0, description="pause between send retries when the tx queue is full")

    @field_validator("interface")
    @classmethod
    def _spec(cls, v: str) -> str:
        from protocol.canbus import parse_can_spec  # local: keeps python-can out of config import time
        try:
            parse_can_spec(v)
        except ConfigError as err:
            raise ValueError(str(err)) from None
        return v

    @field_validator("node_ids")
    @classmethod
    def _nodes(cls, v: tuple[int, ...]) -> tuple[int, ...]:
        if not v or len(set(v)) != len(v) or any(not 1 <= n <= 63 for n in v):
            raise ValueError("node_ids must be distinct CAN node ids in 1..63 (can_id = node_id << 5 | cmd_id)")
        return v


class ZenohTlsConfig(_Frozen):
    """TLS with mutual authentication on every Zenoh link (docs/security.md). PEM paths, relative to the CWD."""
    enabled: bool = False
    root_ca_certificate: str = Field("", description="CA that signed every node certificate")
    certificate: str = Field("", description="this node's certificate (its CN is its identity)")
    private_key: str = Field("", description="this node's private key")
    verify_name_on_connect: bool = Field(True, description="check the listener's certificate names its address")

    @model_validator(mode="after")
    def _paths(self) -> ZenohTlsConfig:
        missing = [n for n in ("root_ca_certificate", "certificate", "private_key") if not getattr(self, n)]
        if self.enabled and missing:
            raise ValueError(f"tls enabled but {', '.join(missing)} not set")
        return self


class ZenohAclConfig(_Frozen):
    """Zenoh access control by certificate CN (docs/security.md): everything not allowed is denied."""
    enabled: bool = False
    controller_cn: str = Field("sea-hil-controller", min_length=1, description="only CN that may command")
    edge_cn: str = Field("sea-hil-edge", min_length=1, description="only CN that may publish the limb state")


class ZenohConfig(_Frozen):
    """Zenoh session and key layout (see docs/zenoh-protocol.md)."""
    prefix: str = "sea"
    limb: str = "limb1"
    mode: Literal["peer", "client"] = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    state_period_s: float = Field(0.01, gt=0)
    tls: ZenohTlsConfig = ZenohTlsConfig()
    acl: ZenohAclConfig = ZenohAclConfig()

    @model_validator(mode="after")
    def _secure_profile(self) -> ZenohConfig:
        if self.acl.enabled and not self.tls.enabled:
            raise ValueError("acl needs tls (identities are certificate CNs): set zenoh.tls.enabled = true")
        plain = [ep for ep in (*self.listen, *self.connect) if not ep.startswith("tls/")]
        if self.tls.enabled and plain:
            raise ValueError(f"tls enabled: endpoints must be tls/HOST:PORT, not {', '.join(plain)}")
        return self

    @field_validator("prefix", "limb")
    @classmethod
    def _key_chunk(cls, v: str, info: Any) -> str:
        from protocol.keys import validate_limb, validate_prefix
        try:
            return validate_prefix(v) if info.field_name == "prefix" else validate_limb(v)
        except ConfigError as err:
            raise ValueError(str(err)) from None


class LinkDirectionConfig(_Frozen):
    delay_s: float = Field(0.0, ge=0)
    jitter_s: float = Field(0.0, ge=0)
    jitter_dist: Literal["uniform", "normal", "exponential"] = "uniform"
    loss: float = Field(0.0, ge=0, le=1)
    ge_p_good_to_bad: float = Field(0.0, ge=0, le=1)
    ge_p_bad_to_good: float = Field(1.0, ge=0, le=1)
    ge_loss_bad: float = Field(1.0, ge=0, le=1)
    rate_bps: float = Field(0.0, ge=0, description="0 = unlimited")
    queue_limit_s: float = Field(0.0, ge=0, description="rate-limit queue: drop if waiting would exceed; 0 = no limit")
    reorder: bool = Field(False, description="false = FIFO delivery like one TCP stream; true = jitter may reorder")


class LinkConfig(_Frozen):
    seed: int = 0
    uplink: LinkDirectionConfig = LinkDirectionConfig()
    downlink: LinkDirectionConfig = LinkDirectionConfig()


class RecordConfig(_Frozen):
    compression: Literal["zstd", "lz4", "none"] = "zstd"
    chunk_size_bytes: int = Field(1 << 20, gt=0)
    stats_period_s: float = Field(1.0, gt=0)
    queue_limit: int = Field(100_000, gt=0)
    flush_period_s: float = Field(1.0, ge=0, description="close the open chunk at least this often; 0 = only when full")


class SeaHilConfig(_Frozen):
    plant: PlantConfig
    disturbance: DisturbanceConfig = DisturbanceConfig()
    trajectory: TrajectoryConfig = TrajectoryConfig()
    controller: ControllerConfig
    trigger: TriggerConfig
    sim: SimConfig = SimConfig()
    can: CanConfig = CanConfig()
    zenoh: ZenohConfig = ZenohConfig()
    link: LinkConfig = LinkConfig()
    record: RecordConfig = RecordConfig()

    @field_validator("plant")
    @classmethod
    def _finite(cls, v: PlantConfig) -> PlantConfig:
        for name, val in v.model_dump().items():
            vals = val if isinstance(val, (tuple, list)) else (val,)
            if any(isinstance(x, float) and not math.isfinite(x) for x in vals):
                raise ValueError(f"plant.{name} must be finite")
        return v


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, val in over.items():
        if isinstance(val, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], val)
        else:
            out[key] = val
    return out


def default_toml_text() -> str:
    return resources.files("protocol").joinpath("default_config.toml").read_text(encoding="utf-8")


def _one_line(err: ValidationError) -> str:
    parts = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        parts.append(f"{loc}: {e['msg']}")
    return "; ".join(parts)


def config_from_dict(data: dict[str, Any]) -> SeaHilConfig:
    try:
        return SeaHilConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(f"invalid config: {_one_line(err)}") from None


def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None) -> SeaHilConfig:
    """Embedded defaults, overlaid with the TOML file at `path` (if any), then `overrides` (nested dict)."""
    data = tomllib.loads(default_toml_text())
    if path is not None:
        p = Path(path)
        try:
            user = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ConfigError(f"config file not found: {p}") from None
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"config file {p} is not valid TOML: {err}") from None
        except (OSError, UnicodeDecodeError) as err:
            raise ConfigError(f"cannot read config file {p}: {err}") from None
        data = _merge(data, user)
    if overrides:
        data = _merge(data, overrides)
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
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
        tables = {k: v for k, v in d.items() if isinstance(v, dict)}
        if scalars:
            lines.append(f"[{prefix}]")
            lines.extend(f"{k} = {fmt(v)}" for k, v in scalars.items())
            lines.append("")
        for k, v in tables.items():
            emit(f"{prefix}.{k}" if prefix else k, v)

    emit("", cfg.model_dump(mode="python"))
    return "\n".join(lines)
