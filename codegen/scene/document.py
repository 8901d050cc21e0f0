"""A Scene back as the document a scene file holds (the reader's input): for re-validating a
scene whose numbers a study changed, and for writing it out."""
from __future__ import annotations

from .values import Scene


def scene_document(scene: Scene) -> dict:
    """The TOML document (nested dicts and lists) that reads back as `scene`."""
    links = []
    for link in scene.links:
        links.append({"mass": link.mass, "inertia": link.inertia, "length": link.length,
                      "com": link.com, "com_normal": link.com_normal,
                      "fastening": link.fastening, "damping": link.damping})
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
    document["initial"] = {"angles": list(scene.initial_angles),
                           "velocities": list(scene.initial_velocities)}
    simulation = scene.simulation
    document["simulation"] = {"method": simulation.method, "quadrature": simulation.quadrature,
                              "dt": simulation.dt, "t_end": simulation.t_end}
    return document
