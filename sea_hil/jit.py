"""Optional numba compilation of plain-float hot-path code, from its own source (never a second copy).

`compiled(factory)` takes a kernel factory `factory(fingerprint: str) -> function` and returns
`numba.njit(cache=True)(factory(fingerprint))`, or None when numba is not installed (the caller then runs
`factory("")`, the same body, as plain Python). Every project function the kernel calls, directly or through other
project functions (found from the global names their code uses), is registered with numba's `register_jitable`: the
compiled kernel runs the very functions the live nodes run. Numba's disk cache only watches the kernel's own file, so
the factory must make the kernel a closure that references `fingerprint`, a hash of the source of every module
involved: numba keys its cache on closure contents, so an edit in any callee invalidates the cached machine code.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import logging
import sys
import types
from collections.abc import Callable
from typing import Any, TypeGuard

log = logging.getLogger(__name__)

PROJECT_PACKAGES = ("sea_hil",)


def _is_project_function(obj: object) -> TypeGuard[types.FunctionType]:
    return isinstance(obj, types.FunctionType) and obj.__module__.split(".")[0] in PROJECT_PACKAGES


def project_callees(fn: types.FunctionType) -> list[types.FunctionType]:
    """Project functions that fn calls (transitively), in discovery order, fn itself excluded."""
    seen: dict[int, types.FunctionType] = {}
    stack = [fn]
    while stack:
        cur = stack.pop()
        for name in cur.__code__.co_names:
            obj = cur.__globals__.get(name)
            if _is_project_function(obj) and id(obj) not in seen and obj is not fn:
                seen[id(obj)] = obj
                stack.append(obj)
    return list(seen.values())


def source_fingerprint(functions: list[Callable[..., Any]]) -> str:
    """sha256 over the source files of the modules defining `functions` (module constants included)."""
    digest = hashlib.sha256()
    for module_name in sorted({f.__module__ for f in functions}):
        digest.update(module_name.encode())
        digest.update(inspect.getsource(sys.modules[module_name]).encode())
    return digest.hexdigest()


@functools.cache
def compiled(factory: Callable[[str], Callable[..., Any]]) -> Any | None:
    """The numba dispatcher of factory's kernel (compiled lazily on first call, cached on disk), or None."""
    if importlib.util.find_spec("numba") is None:
        log.info("numba is not installed: %s runs as plain Python", factory.__qualname__)
        return None
    from numba.core.compiler_lock import global_compiler_lock

    # numba builds its CPU target context (refresh -> load_additional_registries, which imports and registers the
    # numpy-polynomial boxers) on the first dispatcher of a process, outside its compiler lock. Two node threads of
    # an in-process session creating their first kernels at once raced there ("duplicate registration for
    # PolynomialType", seen in a pytest-xdist run). The compiler lock (reentrant, held by numba while it compiles or
    # loads from its cache) serialises registration and dispatcher creation with any compilation in flight; the
    # inner cache makes a second thread that missed the outer cache at the same time get the same dispatcher.
    with global_compiler_lock:
        return _dispatcher(factory)


@functools.cache
def _dispatcher(factory: Callable[[str], Callable[..., Any]]) -> Any:
    import numba
    from numba.extending import register_jitable

    probe = factory("")
    assert isinstance(probe, types.FunctionType), f"{factory.__qualname__} must return a plain function"
    callees = project_callees(probe)
    for fn in callees:
        register_jitable(fn)
    fingerprint = source_fingerprint([factory, *callees])
    return numba.njit(cache=True)(factory(fingerprint))


def loaded(factory: Callable[[str], Callable[..., Any]]) -> Any | None:
    """`compiled(factory)` if a kernel of factory already ran in this process (so calling it costs no import, no
    compilation and no cache load), else None: lets a hot loop use a kernel its owner prepared before the loop
    started and fall back to plain Python otherwise, never stalling on a first call."""
    if "numba" not in sys.modules:
        return None
    kernel = compiled(factory)
    return kernel if kernel is not None and kernel.overloads else None


def entry(kernel: Any, args: tuple[Any, ...]) -> Callable[..., Any]:
    """The compiled entry point of `kernel` (a numba dispatcher) for the numba types of `args`: the machine code the
    dispatcher would run for them, without its typing of every argument on every call (most of the cost of a short
    call: 20 us of 27 for the offline engine's kernel). For a call site whose arguments keep exactly these types
    (plain floats, ints and bools, tuples of them, the same parameter tuples' types, float arrays); a plain-Python
    kernel (no numba) is returned as it is."""
    overloads = getattr(kernel, "overloads", None)
    if overloads is None:
        return kernel
    import numba

    sig = tuple(numba.typeof(a) for a in args)
    if sig not in overloads:
        kernel.compile(sig)
    return overloads[sig].entry_point
