"""The import graph of `sea_hil`, built statically (ast over the source files, the `[tool.setuptools.package-dir]`
mapping resolved: `protocol/` is `sea_hil.protocol`, ...): no cycle between modules or between packages, no
function-local import except one keeping an optional dependency optional, and one import path per name (nothing is
imported from a module that did not define it: no re-export facades).

Every import counts, wherever it is (module level, inside a function, under `if TYPE_CHECKING:`): a cycle is a cycle
of dependencies, whether or not Python would trip over it at import time."""
from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ROOT = "sea_hil"
# Where the rest of the repository imports `sea_hil` from: checked for one import path per name too.
USER_DIRS = ("tests", "bench", "examples", "scripts")
# The package root's public API (docs/api.md: `sea_hil.Session`, ...) is the one re-export: its `__getattr__` imports
# each public name from its defining module on first use. Nothing inside the repository imports through it.
PUBLIC_API_ROOT = "sea_hil"
_NUMBA = "numba is optional: sea_hil.jit runs the kernels as plain Python without it"
_PLUGIN = ("a pytest11 entry point is imported by every pytest process of the environment: sea-hil is loaded only "
           "when a test asks for one of its fixtures")
# Function-local imports that keep a dependency optional (or out of processes that never use it). Each entry:
# (module, imported module) -> why. Anything else at function level is a finding.
LOCAL_IMPORTS_ALLOWED: dict[tuple[str, str], str] = {
    ("sea_hil.jit", "numba"): _NUMBA,
    ("sea_hil.jit", "numba.core.compiler_lock"): _NUMBA,
    ("sea_hil.jit", "numba.extending"): _NUMBA,
    ("sea_hil.plant_emulator.integrator", "numba"): _NUMBA,
    ("sea_hil.plant_emulator.batch", "numba"): _NUMBA,
    ("sea_hil.pytest_plugin", "sea_hil.config.loader"): _PLUGIN,
    ("sea_hil.pytest_plugin", "sea_hil.api"): _PLUGIN,
    ("sea_hil.pytest_plugin", "sea_hil.protocol.canbus"): _PLUGIN,
    ("sea_hil.controller.trajectory", "scipy.interpolate"): (
        "CSV trajectories only: scipy.interpolate takes 0.4-1.7 s to import (measured on this machine), paid "
        "otherwise by every node process at start-up for the default gait, which does not use it"),
}


@dataclass
class Module:
    name: str
    path: Path
    is_package: bool
    tree: ast.Module
    defined: set[str] = field(default_factory=set)


def package_dirs(repo: Path = REPO) -> dict[str, Path]:
    """Import name -> source folder, from pyproject.toml (the mapping the installs use)."""
    with (repo / "pyproject.toml").open("rb") as handle:
        mapping = tomllib.load(handle)["tool"]["setuptools"]["package-dir"]
    return {name: repo / folder for name, folder in mapping.items()}


def module_name(path: Path, dirs: dict[str, Path]) -> str | None:
    """The import name of a source file under the mapping (the longest mapped folder that holds it)."""
    best: tuple[int, str] | None = None
    for name, folder in dirs.items():
        try:
            rel = path.relative_to(folder)
        except ValueError:
            continue
        parts = [*rel.parts[:-1], rel.stem] if rel.stem != "__init__" else list(rel.parts[:-1])
        candidate = ".".join([name, *parts])
        depth = len(folder.parts)
        if best is None or depth > best[0]:
            best = (depth, candidate)
    return None if best is None else best[1]


def load_modules(repo: Path = REPO) -> dict[str, Module]:
    dirs = package_dirs(repo)
    modules: dict[str, Module] = {}
    for folder in {p.resolve() for p in dirs.values()}:
        for path in sorted(folder.rglob("*.py")):
            name = module_name(path, dirs)
            if name is None or not (path.parent / "__init__.py").exists():
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            modules[name] = Module(name, path, path.name == "__init__.py", tree, top_level_definitions(tree))
    return modules


def _top_level_statements(body: Iterable[ast.stmt]) -> Iterator[ast.stmt]:
    """Module-level statements, looking into if/try/with blocks (not into functions or classes)."""
    for stmt in body:
        yield stmt
        if isinstance(stmt, ast.If | ast.With):
            yield from _top_level_statements(stmt.body)
            yield from _top_level_statements(getattr(stmt, "orelse", []))
        elif isinstance(stmt, ast.Try):
            yield from _top_level_statements(stmt.body)
            for handler in stmt.handlers:
                yield from _top_level_statements(handler.body)
            yield from _top_level_statements(stmt.orelse)
            yield from _top_level_statements(stmt.finalbody)


def _targets(node: ast.expr) -> Iterator[str]:
    if isinstance(node, ast.Name):
        yield node.id
    elif isinstance(node, ast.Tuple | ast.List):
        for elt in node.elts:
            yield from _targets(elt)
    elif isinstance(node, ast.Starred):
        yield from _targets(node.value)


def top_level_definitions(tree: ast.Module) -> set[str]:
    """The names a module defines itself (def, class, assignment); imported names are not among them."""
    names: set[str] = set()
    for stmt in _top_level_statements(tree.body):
        if isinstance(stmt, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(stmt.name)
        elif isinstance(stmt, ast.Assign):
            for target in stmt.targets:
                names.update(_targets(target))
        elif isinstance(stmt, ast.AnnAssign | ast.AugAssign):
            names.update(_targets(stmt.target))
    return names


@dataclass(frozen=True)
class Import:
    source: str          # the importing module
    target: str          # the imported module (a `sea_hil` module, or any other top-level name)
    names: tuple[str, ...]   # `from target import names` (empty for `import target`)
    lineno: int
    local: bool          # inside a function


def _resolve_relative(module: Module, level: int, name: str | None) -> str:
    base = module.name.split(".")
    if not module.is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


def imports_of(module: Module, known: Iterable[str]) -> list[Import]:
    """Every import statement of a module; `from pkg import sub` of a submodule is an import of `pkg.sub`."""
    known = set(known)
    found: list[Import] = []
    local_nodes = {id(n) for fn in ast.walk(module.tree) if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
                   for n in ast.walk(fn) if isinstance(n, ast.Import | ast.ImportFrom)}
    for node in ast.walk(module.tree):
        local = id(node) in local_nodes
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append(Import(module.name, alias.name, (), node.lineno, local))
        elif isinstance(node, ast.ImportFrom):
            target = _resolve_relative(module, node.level, node.module) if node.level else node.module or ""
            plain = []
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in known:
                    found.append(Import(module.name, sub, (), node.lineno, local))
                else:
                    plain.append(alias.name)
            if plain:
                found.append(Import(module.name, target, tuple(plain), node.lineno, local))
    return found


def _internal(target: str, modules: dict[str, Module]) -> str | None:
    """The `sea_hil` module an import names (`sea_hil.a.b` where only `sea_hil.a` exists: `sea_hil.a`)."""
    while target:
        if target in modules:
            return target
        target = target.rpartition(".")[0]
    return None


def module_graph(modules: dict[str, Module]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for module in modules.values():
        for imp in imports_of(module, modules):
            target = _internal(imp.target, modules)
            if target is not None and target != module.name:
                graph[module.name].add(target)
    return graph


def package_of(name: str, modules: dict[str, Module]) -> str:
    """The package a module counts under: `sea_hil.<sub>` for what lies in a subpackage; a module directly in
    `sea_hil` (errors, mechanics, api, cli, ...) is a node of its own."""
    parts = name.split(".")
    if len(parts) >= 2 and f"{parts[0]}.{parts[1]}" in modules and modules[f"{parts[0]}.{parts[1]}"].is_package:
        return f"{parts[0]}.{parts[1]}"
    return name


def package_graph(modules: dict[str, Module]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for source, targets in module_graph(modules).items():
        src = package_of(source, modules)
        graph.setdefault(src, set())
        for target in targets:
            dst = package_of(target, modules)
            if dst != src:
                graph[src].add(dst)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One concrete cycle (a -> b -> ... -> a) for each strongly connected component larger than one node."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:   # Tarjan, recursive: the graph is a few hundred nodes
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return [_one_cycle(graph, set(c)) for c in components]


def _one_cycle(graph: dict[str, set[str]], component: set[str]) -> list[str]:
    """A shortest cycle through the component's first node (breadth-first inside the component)."""
    start = min(component)
    parents: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & component):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(parents[path[-1]])
                    return [*reversed(path), start]
                if w not in parents:
                    parents[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start}")


def local_imports(modules: dict[str, Module]) -> list[str]:
    """Function-level imports not in LOCAL_IMPORTS_ALLOWED, as 'path:line: module imports target'."""
    out = []
    for module in modules.values():
        for imp in imports_of(module, modules):
            if imp.local and (module.name, imp.target) not in LOCAL_IMPORTS_ALLOWED:
                out.append(f"{module.path.relative_to(REPO)}:{imp.lineno}: {module.name} imports {imp.target}")
    return sorted(out)


def _user_files(repo: Path) -> Iterator[Path]:
    for folder in USER_DIRS:
        for path in sorted((repo / folder).rglob("*.py")):
            if "node_modules" not in path.parts:
                yield path


def reexports(modules: dict[str, Module], repo: Path = REPO) -> list[str]:
    """Every `from M import N` (in `sea_hil` and in tests/bench/examples/scripts) where M is a `sea_hil` module that
    does not define N itself, every `import *` of one, and every `__all__` naming a name its module did not define;
    the public API root (`PUBLIC_API_ROOT`) apart."""
    out = []
    sources: list[tuple[Path, Module | None, ast.Module]] = [(m.path, m, m.tree) for m in modules.values()]
    sources += [(p, None, ast.parse(p.read_text(encoding="utf-8"), filename=str(p))) for p in _user_files(repo)]
    for path, module, tree in sources:
        where = path.relative_to(repo)
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                if module is None:
                    continue
                target = _resolve_relative(module, node.level, node.module)
            else:
                target = node.module or ""
            if target not in modules or target == PUBLIC_API_ROOT and module is None:
                continue   # users' `from sea_hil import Session`: the public API
            for alias in node.names:
                if alias.name == "*":
                    out.append(f"{where}:{node.lineno}: `from {target} import *`")
                elif f"{target}.{alias.name}" not in modules and alias.name not in modules[target].defined:
                    out.append(f"{where}:{node.lineno}: {alias.name} imported from {target}, which does not "
                               "define it")
        if module is not None and module.name != PUBLIC_API_ROOT:
            for name in _dunder_all(tree):
                if name not in module.defined and f"{module.name}.{name}" not in modules:
                    out.append(f"{where}: __all__ lists {name}, not defined there")
    return sorted(out)


def _dunder_all(tree: ast.Module) -> list[str]:
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in stmt.targets):
            value = stmt.value
            if isinstance(value, ast.List | ast.Tuple):
                return [e.value for e in value.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


@pytest.fixture(scope="module")
def modules() -> dict[str, Module]:
    return load_modules()


def test_the_mapping_is_resolved(modules: dict[str, Module]) -> None:
    assert modules["sea_hil.protocol.keys"].path == REPO / "protocol" / "keys.py"
    assert modules["sea_hil.controller"].is_package and modules["sea_hil.config.loader"].path.parent.name == "config"
    assert "sea_hil.plant_emulator.driver" in module_graph(modules)["sea_hil.plant_emulator.node"]


def test_no_module_cycle(modules: dict[str, Module]) -> None:
    found = cycles(module_graph(modules))
    assert not found, "import cycles between modules:\n" + "\n".join(" -> ".join(c) for c in found)


def test_no_package_cycle(modules: dict[str, Module]) -> None:
    found = cycles(package_graph(modules))
    assert not found, "import cycles between packages:\n" + "\n".join(" -> ".join(c) for c in found)


def test_no_function_local_import(modules: dict[str, Module]) -> None:
    found = local_imports(modules)
    assert not found, "function-local imports (move them to the top, or list them in LOCAL_IMPORTS_ALLOWED with " \
                      "the optional dependency they keep optional):\n" + "\n".join(found)


def test_every_allowed_local_import_exists(modules: dict[str, Module]) -> None:
    used = {(m.name, i.target) for m in modules.values() for i in imports_of(m, modules) if i.local}
    assert set(LOCAL_IMPORTS_ALLOWED) <= used, f"stale entries: {sorted(set(LOCAL_IMPORTS_ALLOWED) - used)}"


def test_one_import_path_per_name(modules: dict[str, Module]) -> None:
    found = reexports(modules)
    assert not found, "names imported from a module that does not define them (import from the defining " \
                      "module):\n" + "\n".join(found)


def test_a_node_command_loads_only_what_its_node_needs() -> None:
    """With the imports at module level, the CLI imports only the module of the command being run: a session's
    controller child (`sea-hil controller`) loads neither the sweep's Dask nor matplotlib nor scipy."""
    code = ("import sys; from sea_hil.cli import build_parser; build_parser('controller'); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'distributed', 'dask', 'matplotlib', 'scipy'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.strip() == "[]"


def test_the_checks_catch_a_cycle_and_a_facade(tmp_path: Path) -> None:
    """The checks themselves, on a toy tree with the same kind of package-dir mapping."""
    (tmp_path / "pyproject.toml").write_text('[tool.setuptools.package-dir]\n"sea_hil" = "sea_hil"\n'
                                             '"sea_hil.protocol" = "protocol"\n', encoding="utf-8")
    (tmp_path / "sea_hil" / "config").mkdir(parents=True)
    (tmp_path / "protocol").mkdir()
    for init in ("sea_hil", "sea_hil/config", "protocol"):
        (tmp_path / init / "__init__.py").write_text("", encoding="utf-8")
    (tmp_path / "sea_hil" / "config" / "model.py").write_text(
        "def check():\n    from sea_hil.protocol.keys import KEY\n    return KEY\n", encoding="utf-8")
    (tmp_path / "protocol" / "keys.py").write_text("from sea_hil.config.model import check\nKEY = 1\n",
                                                   encoding="utf-8")
    (tmp_path / "protocol" / "facade.py").write_text("from .keys import KEY\n__all__ = ['KEY']\n", encoding="utf-8")
    (tmp_path / "sea_hil" / "user.py").write_text("from sea_hil.protocol.facade import KEY\n", encoding="utf-8")
    toy = load_modules(tmp_path)
    assert cycles(module_graph(toy)) == [["sea_hil.config.model", "sea_hil.protocol.keys", "sea_hil.config.model"]]
    assert cycles(package_graph(toy)) == [["sea_hil.config", "sea_hil.protocol", "sea_hil.config"]]
    found = reexports(toy, tmp_path)
    assert any("KEY imported from sea_hil.protocol.facade" in f for f in found)
    assert any("__all__ lists KEY" in f for f in found)
    imports = imports_of(toy["sea_hil.config.model"], toy)
    assert [(i.target, i.local) for i in imports] == [("sea_hil.protocol.keys", True)]
