"""Config sections of the wire and the recording: CAN, Zenoh (TLS, ACL), link emulation, MCAP recording."""
from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from sea_hil.config.base import _Frozen
from sea_hil.config.wire_names import parse_can_spec, validate_limb, validate_prefix
from sea_hil.errors import ConfigError


class Cia402Config(_Frozen):
    """`[can.cia402]`: the CANopen CiA 402 profile (`[can] profile = "cia402"`, docs/cia402.md)."""
    node_ids: tuple[int, ...] = Field((1, 2), description="CANopen node ids, (hip, knee) per limb: each SEA is its "
                                      "own node")
    rated_torque_mnm: int = Field(1000, gt=0, le=2**32 - 1, description="0x6076: the motor torque the ideal "
                                  "current loop delivers at the plant's voltage limit (docs/cia402.md)")

    @field_validator("node_ids")
    @classmethod
    def _nodes(cls, v: tuple[int, ...]) -> tuple[int, ...]:
        if not v or len(v) % 2 or len(set(v)) != len(v) or any(not 1 <= n <= 127 for n in v):
            raise ValueError("cia402.node_ids must be distinct CANopen node ids in 1..127, two (hip, knee) per limb")
        return v


class CanConfig(_Frozen):
    interface: str = "virtual:sea-hil"
    profile: Literal["sea", "cia402"] = Field("sea", description="sea = the DBC protocol (protocol/sea.dbc); "
                                              "cia402 = CANopen CiA 301/402, one node per SEA (docs/cia402.md)")
    cia402: Cia402Config = Cia402Config()
    bitrate_bps: int = Field(1_000_000, gt=0, description="nominal (arbitration-phase) bit rate; classic CAN's only "
                             "rate")
    fd: bool = Field(False, description="CAN FD profile: VOLTAGE_CMD_FD and one FEEDBACK_FD frame per sample, data "
                     "phase at data_bitrate_bps (docs/can-protocol.md); false = classic CAN")
    data_bitrate_bps: int = Field(5_000_000, gt=0, description="CAN FD data-phase bit rate (bit rate switch when "
                                  "above bitrate_bps)")
    emulate_bitrate: bool = Field(False, description="bus-timing model: a frame is delivered when its transmission "
                                  "on the configured bit rates would end, queued by CAN id priority "
                                  "(sea_hil.protocol.bus_timing); false = as fast as the bus delivers")
    bus_load_warn_pct: float = Field(80.0, gt=0, description="a session warns at start when the planned load of a "
                                     "bus is above this")
    node_ids: tuple[int, ...] = (1,)
    feedback_rate_hz: float = Field(1000.0, gt=0, description="drive feedback rate = the inner (backstepping) loop "
                                    "rate, offline and in sessions")
    heartbeat_rate_hz: float = Field(10.0, gt=0)
    watchdog_timeout_s: float = Field(0.1, gt=0)
    send_retries: int = Field(5, ge=0)

    @field_validator("interface")
    @classmethod
    def _spec(cls, v: str) -> str:
        try:
            parse_can_spec(v)
        except ConfigError as err:
            raise ValueError(str(err)) from err
        return v

    @model_validator(mode="after")
    def _rates(self) -> CanConfig:
        if self.fd and self.data_bitrate_bps < self.bitrate_bps:
            raise ValueError(f"data_bitrate_bps {self.data_bitrate_bps} below bitrate_bps {self.bitrate_bps}: the "
                             "CAN FD data phase is never slower than the arbitration phase")
        return self

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
        try:
            return validate_prefix(v) if info.field_name == "prefix" else validate_limb(v)
        except ConfigError as err:
            raise ValueError(str(err)) from err


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
    trace_path: str = Field("", description="CSV trace t_s,delay_s,lost replayed per packet (looped) in place of "
                            "delay, jitter, loss and Gilbert-Elliott; '' = the statistical model")

    @model_validator(mode="after")
    def _trace_alone(self) -> LinkDirectionConfig:
        if self.trace_path and (self.delay_s or self.jitter_s or self.loss or self.ge_p_good_to_bad):
            raise ValueError("a link trace gives the delay and loss itself: do not combine trace with delay, "
                             "jitter, loss or ge")
        return self


class LinkConfig(_Frozen):
    seed: int = 0
    uplink: LinkDirectionConfig = LinkDirectionConfig()
    downlink: LinkDirectionConfig = LinkDirectionConfig()


class RecordConfig(_Frozen):
    compression: Literal["zstd", "lz4", "none"] = "zstd"
    chunk_size_bytes: int = Field(1 << 20, gt=0)
    queue_limit: int = Field(100_000, gt=0)
    flush_period_s: float = Field(1.0, ge=0, description="close the open chunk at least this often; 0 = only when full")
