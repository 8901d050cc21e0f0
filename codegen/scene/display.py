"""Values in messages as a scene file or a sweep spec (TOML) writes them, on one line and
shortened if long: `got "rk4"`, `got 21`, `got [1, 2]`. The scene reader and the rules of a
solver request (chaingen.scene.solver_rules) show every refused value this way."""
from __future__ import annotations

import json
import numbers
import re
from typing import Any

#: A shown value longer than this is cut, with "..." at the end.
SHOW_LIMIT = 120
#: Nesting that `shown` writes out; deeper arrays and tables are shown as "...".
SHOW_DEPTH = 8

_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def shown(value: Any, depth: int = 0) -> str:
    """A value as it would be written in TOML, on one line and shortened if long (numbers
    from numpy as the Python number of their value)."""
    if depth > SHOW_DEPTH and isinstance(value, (list, dict)):
        return "..."
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, (int, float)):
        text = repr(value)
    elif isinstance(value, numbers.Integral):
        text = repr(int(value))
    elif isinstance(value, numbers.Real):
        text = repr(float(value))
    elif isinstance(value, str):
        text = json.dumps(value, ensure_ascii=False)
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(shown(item, depth + 1) for item in value) + "]"
    elif isinstance(value, dict):
        text = "{" + ", ".join(f"{key} = {shown(item, depth + 1)}"
                               for key, item in value.items()) + "}"
    elif hasattr(value, "isoformat"):
        text = value.isoformat()
    else:
        text = repr(value)
    text = printable(text)
    if len(text) > SHOW_LIMIT:
        text = text[: SHOW_LIMIT - 3] + "..."
    return text


def printable(text: str) -> str:
    """Control characters (newlines, carriage returns, ...) written as escapes: one line."""
    return _CONTROL.sub(lambda match: match.group().encode("unicode_escape").decode(), text)


def kind(value: Any) -> str:
    """What a message calls a value's TOML type: "a boolean", "an array" ..."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a float"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return "a date/time"
