"""sea-hil: networked HIL emulator for event-triggered SMC of a 2-DOF SEA lower limb.

One import package. The user's folders are installed inside it: `protocol/` is `sea_hil.protocol` (the wire),
`plant_emulator/` is `sea_hil.plant_emulator` (the emulated drive), `controller/` is `sea_hil.controller` (edge and
remote controller). Shared below them: `sea_hil.errors`, `sea_hil.config`, `sea_hil.mechanics`, `sea_hil.jit`,
`sea_hil.stats`, `sea_hil.runtime` (the `Node` base every node is, the real-time and lockstep clocks). Above them:
`sea_hil.recorder` (MCAP), `sea_hil.session` (`SessionBuilder`, multi-process sessions),
`sea_hil.offline` (offline closed loop), `sea_hil.sweep`, `sea_hil.report`, `sea_hil.commands` and `sea_hil.cli`.
"""

# The public API (docs/api.md), loaded on first use so that importing any part of the package stays light.
__all__ = ["DriveSnapshot", "EmulatedDriver", "SeaHilConfig", "SeaHilError", "Session", "__version__", "load_config"]


def __getattr__(name: str) -> object:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version
        try:
            return version("sea-hil")
        except PackageNotFoundError:   # a source tree that is not installed
            return "0+unknown"
    if name in __all__:
        from sea_hil import api
        return getattr(api, name)
    raise AttributeError(f"module 'sea_hil' has no attribute {name!r}")
