"""`[[limbs]]`: the limbs a session emulates, as data (docs/session.md, "Several limbs").

Each limb is a 2-DOF hip+knee pair with its own CAN node id (`can_id = node_id << 5 | cmd_id`), its own CAN bus
(a `--can` spec; empty = `[can] interface`) and its own Zenoh key chunk (`<prefix>/<name>/...`). An empty list (the
default) is one limb: `[zenoh] limb`, the first of `[can] node_ids`, `[can] interface` -- today's single limb, keys
unchanged. `sea-hil run --limbs N` expands that default limb N times (`sea_hil.session.limbs.expand_limbs`).
"""
from __future__ import annotations

from pydantic import Field, field_validator

from sea_hil.config.base import _Frozen
from sea_hil.config.wire_names import parse_can_spec, validate_limb
from sea_hil.errors import ConfigError


class LimbConfig(_Frozen):
    name: str = Field(description="Zenoh key chunk of the limb (`<prefix>/<name>/state`, ...)")
    node_id: int = Field(ge=1, le=63, description="CAN node id of the limb's drive (both joints)")
    bus: str = Field("", description="CAN spec of the limb's bus; empty = [can] interface")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        try:
            return validate_limb(v)
        except ConfigError as err:
            raise ValueError(str(err)) from err

    @field_validator("bus")
    @classmethod
    def _bus(cls, v: str) -> str:
        if v:
            try:
                parse_can_spec(v)
            except ConfigError as err:
                raise ValueError(str(err)) from err
        return v


def check_limbs(limbs: tuple[LimbConfig, ...]) -> tuple[LimbConfig, ...]:
    """Names and node ids are unique over all limbs (node ids: the recording tells limbs apart by them)."""
    for what in ("name", "node_id"):
        values = [getattr(limb, what) for limb in limbs]
        dup = sorted({str(v) for v in values if values.count(v) > 1})
        if dup:
            raise ValueError(f"limbs: {what} must be unique, repeated: {', '.join(dup)}")
    return limbs
