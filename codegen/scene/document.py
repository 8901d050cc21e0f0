"""A Scene back as the document a scene file holds (the reader's input): for re-validating a
scene whose numbers a study changed, and for writing it out."""
from __future__ import annotations

import json

from .values import LINK_FIELDS, Scene


def scene_document(scene: Scene) -> dict:
    """The TOML document (nested dicts and lists) that reads back as `scene`."""
    links = []
    for link in scene.links:
        links.append({field.key: getattr(link, field.key) for field in LINK_FIELDS})
    springs = []
    for spring in scene.springs:
        entry = {"joints": [spring.first, spring.last], "stiffness": spring.stiffness,
                 "rest_length": spring.rest_length}
        if spring.offsets is not None:
            entry["offsets"] = list(spring.offsets)
        springs.append(entry)
    document = {"name": scene.name, "gravity": scene.gravity,
                "base": {"fastening": scene.base_fastening}, "links": links, "springs": springs}
    if scene.actuated_joints:
        document["actuation"] = {"joints": list(scene.actuated_joints)}
    if scene.control is not None:
        control = scene.control
        document["control"] = {"target": list(control.target),
                               "stiffness": list(control.stiffness),
                               "damping": list(control.damping),
                               "compensate": control.compensate, "law": control.law}
    document["initial"] = {"angles": list(scene.initial_angles),
                           "velocities": list(scene.initial_velocities)}
    simulation = scene.simulation
    document["simulation"] = {"method": simulation.method, "quadrature": simulation.quadrature,
                              "order": simulation.order, "dt": simulation.dt,
                              "t_end": simulation.t_end}
    return document


def scene_toml(scene: Scene) -> str:
    """The scene as a scene file's text (reads back as `scene`): for writing out a scene a
    study made, e.g. one run of a sweep to simulate on its own."""
    document = scene_document(scene)
    lines = [f"name = {_value(document['name'])}", f"gravity = {_value(document['gravity'])}"]
    for table in ("base", "actuation", "control", "initial", "simulation"):
        if table in document:
            lines += ["", f"[{table}]"]
            lines += [f"{key} = {_value(value)}" for key, value in document[table].items()]
    for table in ("links", "springs"):
        for row in document[table]:
            lines += ["", f"[[{table}]]"]
            lines += [f"{key} = {_value(value)}" for key, value in row.items()]
    return "\n".join(lines) + "\n"


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(item) for item in value) + "]"
    return repr(value)
