"""Key paths spelled one way: one number of a scene, one path (`links[1].mass`, `gravity`).

A path is names joined by dots, each followed by indices in brackets; its canonical spelling has
ASCII names, indices in ASCII digits without leading zeros, and no whitespace. Another spelling of
the same number (`links[01].mass`, `links[١].mass`: Python's \\d matches every script's digits,
` links[1].mass `) is refused, with the canonical spelling in the message, wherever a path is
read: run-time parameters (Solver.parameter_values, `--parameters`), sweep specs, the scene
numbers a study varies (chaingen.scene.parameters). So two spellings of one number can never
stand for two numbers, nor one number be named twice.

Plain data: the standard library only, so the runtime and the generator share it.
"""
from __future__ import annotations

import re

#: One step of a path after its first name: `.name` or `[index]`, spaces allowed around them.
_FIRST = re.compile(r"\s*(\w+)")
_NEXT = re.compile(r"\s*(?:\.\s*(?P<name>\w+)|\[\s*(?P<index>\w+)\s*\])")
_ASCII_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*", re.ASCII)


def canonical_path(path) -> str | None:
    """The canonical spelling of the key path `path`, or None if it has no key path's shape
    (then it names no number, whatever it was meant to be)."""
    if not isinstance(path, str):
        return None
    match = _FIRST.match(path)
    if not match or not _ASCII_NAME.fullmatch(match[1]):
        return None
    parts, position = [match[1]], match.end()
    while True:
        match = _NEXT.match(path, position)
        if not match:
            break
        position = match.end()
        if match["name"] is not None:
            if not _ASCII_NAME.fullmatch(match["name"]):
                return None
            parts.append(f".{match['name']}")
        else:
            if not match["index"].isdecimal():
                return None
            parts.append(f"[{int(match['index'])}]")
    if path[position:].strip():
        return None
    return "".join(parts)


def spelling_error(path) -> str | None:
    """None if `path` is spelled canonically (or is no key path at all: the caller says it names
    no number); else the one-line message naming the canonical spelling."""
    canonical = canonical_path(path)
    if canonical is None or canonical == path:
        return None
    return (f"{path!r}: write {canonical} (one spelling per number: indices in ASCII digits "
            "without leading zeros, no spaces)")
