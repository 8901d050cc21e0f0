"""Reading a scene's [control] table (docs/scene-format.md): energy shaping and damping
injection on the actuated joints (docs/controllers.md, "Passivity-based control")."""
from __future__ import annotations

from typing import Any

from .display import kind
from .values import CONTROL_LAWS, Control, far_angle

_CONTROL_KEYS = ("target", "stiffness", "damping", "compensate", "law")


def read_control(reader, table: dict[str, Any], n: int, actuated: tuple[int, ...]) -> Control:
    """[control]: the target posture (one angle per joint), shaping stiffness and injected
    damping (one per actuated joint), compensate and law (docs/scene-format.md)."""
    if not actuated:
        reader.fail("control", "needs actuated joints: add [actuation] joints = [...] (the "
                               "control law acts on them)")
    count = len(actuated)
    per_joint = f"one per actuated joint {list(actuated)}"
    fields: dict[str, Any] = {}
    for key, item in table.items():
        where = f"control.{key}"
        if key == "target":
            fields[key] = reader.number_list(where, item, "phi*_i in rad", n, "one per joint")
            if refused := far_angle(where, fields[key]):   # as initial.angles: 1.2e-10 rad
                reader.fail(*refused)
        elif key in ("stiffness", "damping"):
            meaning = ("k_a in N m/rad" if key == "stiffness" else "D_a in N m s/rad")
            values = reader.number_list(where, item, meaning, count, per_joint)
            for index, value in enumerate(values):
                if value < 0 or (key == "stiffness" and value == 0):
                    rule = "> 0" if key == "stiffness" else ">= 0"
                    reader.fail(f"{where}[{index}]", f"must be {rule} ({meaning}, joint "
                                                   f"{actuated[index]})", value)
            fields[key] = values
        elif key == "compensate":
            if not isinstance(item, bool):
                reader.fail(where, "must be true or false (cancel the scene's own potential "
                                 f"on the actuated joints), not {kind(item)}", item)
            fields[key] = item
        elif key == "law":
            if item not in CONTROL_LAWS:
                reader.fail(where, "must be one of " + ", ".join(
                    f'"{law}"' for law in CONTROL_LAWS), item)
            fields[key] = item
        else:
            reader.unknown_key("control", key, item, _CONTROL_KEYS)
    for key in ("target", "stiffness"):
        if key not in fields:
            reader.fail(f"control.{key}", "missing: required in [control]")
    fields.setdefault("damping", (0.0,) * count)
    return Control(**fields)
