"""The config a session recording carries (its `config.toml` attachment) and what follows from it for reading the
file back: the effective config, and for a cia402 session the CANopen decoder of its bus."""
from __future__ import annotations

import tomllib

from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import SeaHilError
from sea_hil.protocol.cia402_decode import Cia402Decoder, decoder_for
from sea_hil.recorder.meta import CONFIG_ATTACHMENT
from sea_hil.recorder.reader import SessionData


def session_config(data: SessionData) -> SeaHilConfig | None:
    """The recording's effective config (its `config.toml` attachment), or None when it has none or it is unusable."""
    raw = data.attachments.get(CONFIG_ATTACHMENT)
    if raw is None:
        return None
    try:
        return load_config(overrides=tomllib.loads(raw.decode("utf-8")))
    except (SeaHilError, ValueError):
        return None


def canopen_decoder(data: SessionData) -> Cia402Decoder | None:
    """The CANopen decoder of a cia402 recording's bus (`protocol.cia402_decode`, from its attached config), None
    for any other recording (the sea profile's DBC frames, a recording without a usable config)."""
    cfg = session_config(data)
    return decoder_for(cfg) if cfg is not None and cfg.can.profile == "cia402" else None
