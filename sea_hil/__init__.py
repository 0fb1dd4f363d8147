"""sea-hil: networked HIL emulator for event-triggered SMC of a 2-DOF SEA lower limb.

One import package. The user's folders are installed inside it: `protocol/` is `sea_hil.protocol` (the wire),
`plant_emulator/` is `sea_hil.plant_emulator` (the emulated drive), `controller/` is `sea_hil.controller` (edge and
remote controller). Shared below them: `sea_hil.errors`, `sea_hil.config`, `sea_hil.mechanics`, `sea_hil.jit`,
`sea_hil.stats`, `sea_hil.runtime` (the `Node` base every node is, the real-time and lockstep clocks). Above them:
`sea_hil.recorder` (MCAP), `sea_hil.session` (`SessionBuilder`, multi-process sessions),
`sea_hil.offline` (offline closed loop), `sea_hil.sweep`, `sea_hil.report`, `sea_hil.commands` and `sea_hil.cli`.
"""

from importlib import import_module as _import_module
from importlib import metadata as _metadata

# The public API (docs/api.md): each name from the module that defines it, imported on first use, so that importing
# any part of the package stays light (every `import sea_hil.x` runs this file first). The one re-export of the
# package (tests/test_import_graph.py): inside it, every module imports a name from where it is defined.
_PUBLIC = {"DriveSnapshot": "sea_hil.api", "EmulatedDriver": "sea_hil.api", "Session": "sea_hil.api",
           "SeaHilConfig": "sea_hil.config.root", "load_config": "sea_hil.config.loader",
           "SeaHilError": "sea_hil.errors"}
__all__ = [*sorted(_PUBLIC), "__version__"]


def __getattr__(name: str) -> object:
    if name == "__version__":
        try:
            return _metadata.version("sea-hil")
        except _metadata.PackageNotFoundError:   # a source tree that is not installed
            return "0+unknown"
    if name in _PUBLIC:
        return getattr(_import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'sea_hil' has no attribute {name!r}")
