"""Straight-line Python for one frame plan (`sea_hil.protocol.frame_plan`): the pack and unpack of a message written
out once, when the plan is built, with its shifts, masks, scales and ranges as literals (`repr` of a float reads
back the same float), so a hot frame costs a few integer operations and no loop. The same arithmetic as the plan's
generic `encode` / `decode` (and so as cantools; tests/test_frame_plan.py checks the generated code against it).

- `pack_plain(values) -> bytes | None`: every value an `int` (a `float` allowed on a scaled signal) inside its DBC
  range: the data bytes; anything else: None (the caller takes the checking, saturating path).
- `unpack(data) -> tuple`: the physical values, no checks (the caller checked length and reserved bits).
- `unpack_plain(data) -> tuple | None`: `unpack` when every value is inside its DBC range (and in its value table),
  else None (the caller's checking path decides: clamp within the tolerance, or reject).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any


def _raw_expr(s: Any, v: str) -> str:
    if s.identity:
        return v
    return f"round({v} / {s.scale!r})" if s.offset == 0 else f"round(({v} - {s.offset!r}) / {s.scale!r})"


def _physical_expr(s: Any) -> str:
    field = f"((w >> {s.start}) & {s.mask})" if s.start else f"(w & {s.mask})"
    if s.signed:
        sign = 1 << (s.length - 1)
        field = f"(({field} ^ {sign}) - {sign})"   # two's complement
    return field if s.identity else f"{field} * {s.scale!r} + {s.offset!r}"


def _range_test(s: Any, v: str) -> str:
    test = f"not ({s.minimum!r} <= {v} <= {s.maximum!r})"
    if s.choices:
        test += f" or {v} not in {tuple(sorted(s.choices))!r}"
    return test


def _compile(name: str, lines: list[str], label: str) -> Callable[..., Any]:
    namespace: dict[str, Any] = {}
    code = compile("\n".join(lines), f"<frame plan {label}.{name}>", "exec")   # source built from the DBC only
    exec(code, namespace)  # noqa: S102
    fn: Callable[..., Any] = namespace[name]
    return fn


def generate(plan: Any) -> tuple[Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
    """(pack_plain, unpack, unpack_plain) of `plan`."""
    sigs = plan.signals
    if not sigs:
        empty = bytes(plan.length)
        return (lambda values: empty), (lambda data: ()), (lambda data: ())
    names = [f"v{i}" for i in range(len(sigs))]
    unpacked = ", ".join(names) + ("," if len(names) == 1 else "")
    pack = ["def pack_plain(values):", f"    {unpacked} = values"]
    for s, v in zip(sigs, names, strict=True):
        kinds = "type({v}) is not int" if s.identity else "(type({v}) is not float and type({v}) is not int)"
        pack.append(f"    if {kinds.format(v=v)} or not ({s.minimum!r} <= {v} <= {s.maximum!r}):")
        pack.append("        return None")
    terms = [f"(({_raw_expr(s, v)}) & {s.mask}) << {s.start}" for s, v in zip(sigs, names, strict=True)]
    pack.append(f"    return ({' | '.join(terms) or '0'}).to_bytes({plan.length}, 'little')")
    unpack = ["def unpack(data):", "    w = int.from_bytes(data, 'little')",
              f"    return ({', '.join(_physical_expr(s) for s in sigs)}{',' if len(sigs) == 1 else ''})"]
    plain = ["def unpack_plain(data):", "    w = int.from_bytes(data, 'little')"]
    for s, v in zip(sigs, names, strict=True):
        plain += [f"    {v} = {_physical_expr(s)}", f"    if {_range_test(s, v)}:", "        return None"]
    plain.append(f"    return ({unpacked})")
    return (_compile("pack_plain", pack, plan.name), _compile("unpack", unpack, plan.name),
            _compile("unpack_plain", plain, plan.name))
