"""Frozen configuration objects loaded from TOML.

One `SeaHilConfig` is built per process from the embedded default (`sea_hil/config/default_config.toml`) overlaid with
an optional user file; unknown keys and wrong types are errors (`ConfigError`, one line). Nothing here is global:
callers pass the config object down.
"""
