"""What a generated package depends on, as hashes computed without SymPy or CasADi.

- `input_hash`: of a SolverSpec: the scene's code-relevant numbers, the method and its
  options, and the tool versions. It is the package's identity (the manifest's "input_hash",
  the banner of every generated file), so generated/ stays reproducible byte for byte.
- `solver_key`: input_hash and everything else that decides the compiled library: chaingen's own
  code and templates as installed (an edited template must not load yesterday's build, also in
  an editable install whose version did not move), the compiler and the build flags. It keys the
  build cache's index from inputs to libraries (runtime/build.py), which lets `build_solver`
  load an unchanged solver without running SymPy or CasADi.

The tool versions come from the installed distributions' metadata, which is read without
importing the tools (importing SymPy alone costs about a second).
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.metadata
import importlib.resources
import json
from pathlib import Path

from ..scene import Scene, SolverSpec, quadrature_used
from ..scene.solver_rules import gradient_used
from ..version import VERSION

#: The files of the installed package whose text decides the generated code and its build.
CODE_SUFFIXES = (".py", ".j2", ".h", ".c")


def input_hash(spec: SolverSpec | Scene, method: str | None = None,
               quadrature: int | None = None, sensitivities: bool = True, parameters=(),
               order: int = 2, gradient: str | None = "exact") -> str:
    """sha256 of everything the generated code of a SolverSpec depends on, and nothing else.

    The initial state and the simulation defaults do not enter the code; the tool versions and
    the paths of the run-time parameters do. Also of the fields of a built scheme (scene,
    method, quadrature, sensitivities, parameter paths, order, gradient), which the scheme has
    from its checked SolverSpec: its quadrature and gradient may be the ones in use (None where
    they play no role). The gradient enters only where it plays a role, so the hash of every
    other package is what it was before es had the choice.
    """
    if isinstance(spec, SolverSpec):
        scene, method, quadrature = spec.scene, spec.method, spec.quadrature
        sensitivities, parameters, order = spec.sensitivities, spec.parameters, spec.order
        gradient = spec.gradient
    else:
        scene = spec
    code_relevant = dataclasses.asdict(scene)
    for key in ("initial_angles", "initial_velocities", "simulation"):
        code_relevant.pop(key, None)     # a spatial scene has no simulation defaults
    if code_relevant.get("control", 0) is None:
        del code_relevant["control"]     # the hash of a scene without control is unchanged
    payload = {
        "scene": code_relevant, "method": method,
        "quadrature": quadrature_used(scene, method, quadrature, order),
        "sensitivities": sensitivities, "parameters": list(parameters), "order": order,
        "chaingen": VERSION, "sympy": importlib.metadata.version("sympy"),
        "casadi": importlib.metadata.version("casadi"),
    }
    used = gradient_used(scene, method, gradient, order) if gradient is not None else None
    if used is not None:
        payload["gradient"] = used
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """sha256 over the installed chaingen package's code, templates and C sources and headers
    (paths and contents), computed once a process (a few milliseconds)."""
    # The three folders may live in different places (an editable install maps them).
    return folders_digest([Path(str(importlib.resources.files(package)))
                           for package in ("chaingen", "chaingen.runtime", "chaingen.templates")])


def folders_digest(folders) -> str:
    """sha256 over the CODE_SUFFIXES files under `folders`: their paths relative to their
    folder, and their contents."""
    entries = sorted({(str(path.relative_to(folder)), path) for folder in folders
                      for path in Path(folder).rglob("*")
                      if path.suffix in CODE_SUFFIXES and "__pycache__" not in path.parts})
    digest = hashlib.sha256()
    for name, path in entries:
        digest.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def solver_key(spec: SolverSpec | Scene, method: str | None = None,
               quadrature: int | None = None, *, sensitivities: bool = True, parameters=(),
               order: int = 2, gradient: str = "exact", build: tuple[str, ...] = ()) -> str:
    """The build cache index's key of the solver build_solver makes of a SolverSpec (or of
    the keywords it is made of): input_hash, chaingen's code (code_digest) and `build` (the
    compiler and flags)."""
    if not isinstance(spec, SolverSpec):
        spec = SolverSpec(spec, method, quadrature, order=order, parameters=parameters,
                          sensitivities=sensitivities, gradient=gradient)
    payload = [input_hash(spec), code_digest(), list(build)]
    return hashlib.sha256(json.dumps(payload).encode()).hexdigest()[:32]
