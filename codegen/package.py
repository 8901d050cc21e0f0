"""Render a scheme into a C package: {filename: text} in memory, written to disk separately.

Templates are listed in one table (TEMPLATES); every decision is made here and handed to them
as a context, rendered with StrictUndefined so a missing value fails instead of printing "".
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib.resources
import json
import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi
import jinja2
import sympy

from . import __version__
from chaingen_runtime import JACOBIAN_ACROSS_STEPS, JACOBIAN_PER_STEP
from chaingen_runtime.trajectory import current_umask

from .example import example_settings
from .kinematics import RUN_SEGMENT_RELATIVE_TOLERANCE
from .casadi_functions import casadi_c_source, scheme_functions, work_sizes
from .scene import ChaingenError, Scene
from .schemes import DiscreteScheme, build_scheme

#: template -> file it renders ({prefix} is replaced by the package prefix)
TEMPLATES = {
    "solver.h.j2": "{prefix}.h",
    "solver.c.j2": "{prefix}.c",
    "Makefile.j2": "Makefile",
    "CMakeLists.txt.j2": "CMakeLists.txt",
    "example.c.j2": "example.c",
    "README.md.j2": "README.md",
}
MANIFEST = "chaingen.json"
LU_HEADER = "chaingen_lu.h"

#: Newton defaults written into the generated options (C literals).
NEWTON_DEFAULTS = {
    "max_iterations": 20,
    "update_rtol": "1e-10",
    "update_atol": "1e-13",
    "residual_tol": "1e-8",
    "warm_start": 1,
    "reuse_jacobian": 0,
}
#: A generated model source larger than this is compiled with LARGE_MODEL_FLAGS in place of the
#: optimisation level: on a single function of some 10^5 lines gcc's -O2 takes minutes (n = 20:
#: about 40 s unloaded against 5 s for -O1) for a per-step time within noise of -O1's.
LARGE_MODEL_BYTES = 1_000_000
LARGE_MODEL_FLAGS = ("-O1",)
#: The solver source (Newton loop and the dense LU inlined in it) is compiled with -O3: gcc
#: vectorises the LU's column updates only there, which halves the factorisation at n = 20
#: (60 unknowns) and is neutral at n = 3 (docs/benchmarks.md).
SOLVER_FLAGS = ("-O3",)


def newton_defaults(method: str) -> dict:
    """The Newton defaults of a package. "vi" keeps its Jacobian across steps (simplified
    Newton): it costs six residuals, and the scheme's energy error (O(dt^2)) hides the linear
    convergence. "es" and "midpoint" evaluate it once a step and reuse it within the step: from
    the warm start, the second iterate's chord update is already at round-off, so a step costs
    one Jacobian, one factorisation and two residuals, with the energy balance of full Newton
    (docs/benchmarks.md, speed knobs)."""
    reuse = JACOBIAN_ACROSS_STEPS if method == "vi" else JACOBIAN_PER_STEP
    return {**NEWTON_DEFAULTS, "reuse_jacobian": reuse}

#: A kept Jacobian (simplified Newton, Newton-chord) is evaluated anew when successive updates shrink by less than this.
REFRESH_RATE = "0.1"
#: A kept Jacobian stops when its estimated error is this fraction of the tolerance: simplified
#: Newton (a speed option) at 0.1, Newton-chord (es's default, which must keep full Newton's
#: round-off energy balance) at 1e-3; at dt = 0.1 s on three_link_gravity 0.1 left 1e-12 J.
SIMPLIFIED_MARGIN = "0.1"
CHORD_MARGIN = "1e-3"

METHOD_SUMMARIES = {
    "es": "Energy-stable discrete gradient scheme in COM coordinates with constraints "
          "(model.md section 4).",
    "vi": "Lie-group variational integrator on unit attitude vectors, position-momentum form "
          "(model.md section 5).",
    "midpoint": "Implicit midpoint rule in relative joint angles (model.md section 6).",
}


class PackageWriteError(ChaingenError):
    pass


@dataclass(frozen=True)
class GeneratedPackage:
    """A generated C package: its prefix, its files, and the manifest the runtime reads."""

    prefix: str
    files: dict[str, str]
    manifest: dict

    @property
    def sources(self) -> tuple[str, ...]:
        return tuple(name for name in sorted(self.files) if name.endswith(".c"))


def package_prefix(scene: Scene, method: str) -> str:
    """C prefix of every exported symbol: the scene's C name and the method."""
    return f"{scene.c_name}_{method}"


def uses_quadrature(scene: Scene, method: str) -> bool:
    return method == "es" and bool(scene.springs)


def input_hash(scene: Scene, method: str, quadrature: int, sensitivities: bool = True) -> str:
    """sha256 of everything the generated code depends on, and nothing else.

    The initial state and the simulation defaults do not enter the code; the tool versions do.
    """
    code_relevant = dataclasses.asdict(scene)
    for key in ("initial_angles", "initial_velocities", "simulation"):
        code_relevant.pop(key)
    payload = {
        "scene": code_relevant, "method": method,
        "quadrature": quadrature if uses_quadrature(scene, method) else None,
        "sensitivities": sensitivities,
        "chaingen": __version__, "sympy": sympy.__version__, "casadi": casadi.__version__,
    }
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _environment() -> jinja2.Environment:
    loader = jinja2.FunctionLoader(
        lambda name: importlib.resources.files("chaingen_templates").joinpath(name).read_text())
    return jinja2.Environment(loader=loader, undefined=jinja2.StrictUndefined,
                              keep_trailing_newline=True, autoescape=False)


def scheme_label(scheme: DiscreteScheme) -> str:
    label = f'method "{scheme.method}"'
    if uses_quadrature(scheme.scene, scheme.method):
        label += f", {scheme.quadrature}-point Gauss-Legendre quadrature of the spring terms"
    return label


def sample_columns(n: int, energy_flows: bool = False) -> list[tuple[str, str]]:
    """The trajectory columns of scene-format.md, which are also simulate's sample rows.

    A scene with actuation or damping adds the energy flows since the start, so that
    H - H_0 = input_work - dissipated can be read off every row (model.md 7).
    """
    columns = ([("t", "time (s)")]
               + [(f"phi{i}", f"relative angle of joint {i}, wrapped to (-pi, pi] (rad)")
                  for i in range(1, n + 1)]
               + [(f"omega{i}", f"relative angular velocity of joint {i} (rad/s)")
                  for i in range(1, n + 1)]
               + [("energy", "H = T + V (J)"),
                  ("constraint_error", "largest structural error of the state's coordinates")])
    if energy_flows:
        columns += [("input_work", "work of the joint torques since the start (J)"),
                    ("dissipated", "energy dissipated by joint damping since the start, >= 0 (J)")]
    return columns


#: How each scheme's step measures its energy flows, and what balance they satisfy.
FLOW_DOCS = {
    "es": ("dt sum_i tau_i phidot_i(m)", "dt sum_i d_i phidot_i(m)^2",
           "phidot(m) the joint rates at the step's mid-point, where the torques enter. The "
           "scheme is passive: H_1 - H_0 = flows[0] - flows[1] to quadrature and solver "
           "accuracy (model.md 7)."),
    "vi": ("sum_i tau_i theta_i", "sum_i d_i theta_i^2 / dt",
           "theta the rotation increments of the step. H_1 - H_0 - flows[0] + flows[1] is the "
           "scheme's energy error, O(dt^2)."),
    "midpoint": ("dt sum_i tau_i w_i(m)", "dt sum_i d_i w_i(m)^2",
                 "w(m) the mid-point joint rates. H_1 - H_0 - flows[0] + flows[1] is the "
                 "scheme's energy error, O(dt^2)."),
}


def signature_parts(nu: int, flows: bool) -> dict[str, str]:
    """Pieces of the C signatures that exist only when the scene has inputs or energy flows."""
    return {
        "u_param": "const double *u, " if nu else "", "u_arg": "u, " if nu else "",
        "u_check": "!u || " if nu else "", "u_doc": "u, " if nu else "",
        "u_step_doc": ", with the inputs u[NU] held over the step" if nu else "",
        "du_param": "double *ds_du, " if nu else "", "du_arg": "ds_du, " if nu else "",
        "flows_param": "double *flows, " if flows else "",
        "flows_arg": "flows, " if flows else "", "flows_null": "NULL, " if flows else "",
        "totals_arg": "totals, " if flows else "",
    }


def c_double(value: float) -> str:
    """A double as a C literal that round-trips."""
    text = repr(float(value))
    return text if any(c in text for c in ".en") else text + ".0"


def _example_context(scene: Scene) -> dict:
    settings = example_settings(scene)
    doubles = lambda values: ", ".join(map(c_double, values))  # noqa: E731
    return {
        "initial_angles": doubles(scene.initial_angles),
        "initial_velocities": doubles(scene.initial_velocities),
        "dt": c_double(settings.dt), "duration": c_double(settings.duration),
        "print_every": settings.print_every, "target": doubles(settings.target),
        "actuated_indices": ", ".join(str(j - 1) for j in scene.actuated_joints),
        "kp": doubles(settings.kp), "kd": doubles(settings.kd),
        "bandwidth_hz": f"{settings.bandwidth / (2 * math.pi):.3g}",
    }


#: Stages of generate_package that report progress (a build adds one: compiling).
GENERATE_STAGES = 3


def render_package(scheme: DiscreteScheme, *, sensitivities: bool = True,
                   progress=None) -> GeneratedPackage:
    """The C package of `scheme`: CasADi code for its functions and the templates around it.

    sensitivities=False leaves out step_sensitivities and its generated functions (a package
    only run forward, as `chaingen simulate` does, builds faster without them). progress: a
    codegen.progress.Progress told of each stage.
    """
    scene = scheme.scene
    prefix = package_prefix(scene, scheme.method)
    digest = input_hash(scene, scheme.method, scheme.quadrature, sensitivities)
    if progress is not None:
        progress.update(1, "CasADi functions and derivatives")
    functions = scheme_functions(scheme, prefix, sensitivities=sensitivities)
    if progress is not None:
        progress.update(2, "C code of the model")
    model_source, model_header = casadi_c_source(functions.all(), prefix)
    sizes = work_sizes(functions.all())
    model_flags = LARGE_MODEL_FLAGS if len(model_source) > LARGE_MODEL_BYTES else ()
    source_flags = {f"{prefix}.c": list(SOLVER_FLAGS)}
    if model_flags:
        source_flags[f"{prefix}_model.c"] = list(model_flags)
    defaults = newton_defaults(scheme.method)

    banner_text = (f"Generated by chaingen {__version__} (SymPy {sympy.__version__}, CasADi "
                   f"{casadi.__version__}) for scene \"{scene.name}\", {scheme_label(scheme)}. "
                   f"Do not edit. chaingen_input_hash={digest}")
    c_banner = f"/* {banner_text} */"
    n = scene.n
    nu = len(scene.actuated_joints)
    flows = scheme.has_energy_flows
    columns = sample_columns(n, flows)
    work_doc, dissipated_doc, balance_doc = FLOW_DOCS[scheme.method]
    context = {
        **signature_parts(nu, flows),
        "nu": nu, "actuated_joints": scene.actuated_joints, "flows": flows,
        "sensitivities": sensitivities, "segments": scheme.segment_vectors.shape[0] // 2,
        "segment_tolerance": f"{RUN_SEGMENT_RELATIVE_TOLERANCE:g}",
        "nsens": 2 * n + nu, "flows_work": work_doc, "flows_dissipated": dissipated_doc,
        "flows_balance": balance_doc,
        **_example_context(scene),
        "banner": c_banner, "make_banner": f"# {banner_text}", "banner_text": banner_text,
        "prefix": prefix, "PREFIX": prefix.upper(),
        "scene_name": scene.name, "method": scheme.method, "quadrature": scheme.quadrature,
        "scheme_label": scheme_label(scheme), "method_summary": METHOD_SUMMARIES[scheme.method],
        "n": n, "nx": len(scheme.state_layout), "nz": len(scheme.unknowns_layout),
        "nsample": len(columns), "nconstraint": scheme.constraint_residuals.shape[0],
        "state_entries": scheme.state_layout.entries,
        "state_description": scheme.state_layout.description,
        "unknowns_entries": scheme.unknowns_layout.entries,
        "unknowns_description": scheme.unknowns_layout.description,
        "residual_description": scheme.residual_description,
        "sample_columns": columns,
        "work": {key: max(1, value) for key, value in dataclasses.asdict(sizes).items()},
        "defaults": defaults, "refresh_rate": REFRESH_RATE,
        "simplified_margin": SIMPLIFIED_MARGIN, "chord_margin": CHORD_MARGIN,
        "source_flags": {name: " ".join(flags) for name, flags in source_flags.items()},
        "model_flags": " ".join(model_flags), "large_model_bytes": LARGE_MODEL_BYTES,
        "sources": [f"{prefix}.c", f"{prefix}_model.c"],
    }
    environment = _environment()
    files = {output.format(prefix=prefix): environment.get_template(template).render(context)
             for template, output in TEMPLATES.items()}
    files[f"{prefix}_model.c"] = f"{c_banner}\n{model_source}"
    files[f"{prefix}_model.h"] = f"{c_banner}\n{model_header}"
    files[LU_HEADER] = (importlib.resources.files("chaingen_runtime")
                        .joinpath("c", LU_HEADER).read_text())
    manifest = {
        "chaingen_version": __version__, "input_hash": digest, "prefix": prefix,
        "scene": scene.name, "method": scheme.method,
        "quadrature": scheme.quadrature if uses_quadrature(scene, scheme.method) else None,
        "n_joints": n, "nx": context["nx"], "nz": context["nz"], "nsample": context["nsample"],
        "actuated_joints": list(scene.actuated_joints), "nu": nu, "energy_flows": flows,
        "sensitivities": sensitivities,
        "state": list(scheme.state_layout.entries),
        "unknowns": list(scheme.unknowns_layout.entries),
        "sample_columns": [name for name, _ in columns],
        "sources": context["sources"],
        "source_flags": source_flags,
        "newton_defaults": defaults,
    }
    files[MANIFEST] = json.dumps(manifest, indent=2) + "\n"
    return GeneratedPackage(prefix=prefix, files=dict(sorted(files.items())), manifest=manifest)


def generate_package(scene: Scene, method: str, quadrature: int, *,
                     sensitivities: bool = True, progress=None) -> GeneratedPackage:
    """Scene -> scheme -> C package, all in memory. progress: see render_package."""
    if progress is not None:
        progress.update(0, "deriving the model and the scheme (SymPy)")
    package = render_package(build_scheme(scene, method, quadrature),
                             sensitivities=sensitivities, progress=progress)
    if progress is not None:
        progress.update(GENERATE_STAGES)
    return package


def write_package(package: GeneratedPackage, directory: str | os.PathLike) -> Path:
    """Write the package's files into `directory`, all or nothing.

    The files go to a temporary sibling first and replace `directory` only when all are
    written. An existing directory is replaced only if it is a chaingen package (has a
    manifest) or empty, so a typo in -o cannot wipe unrelated files.
    """
    target = Path(directory)
    if target.exists():
        if not target.is_dir():
            raise PackageWriteError(f"{target}: exists and is not a directory")
        if any(target.iterdir()) and not (target / MANIFEST).is_file():
            raise PackageWriteError(
                f"{target}: exists and is not a chaingen package (no {MANIFEST}); "
                "choose an empty or new directory")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        staging.chmod(0o777 & ~current_umask())   # mkdtemp's 0700 is not what users expect
        for name, text in package.files.items():
            (staging / name).write_text(text)
        if target.exists():
            shutil.rmtree(target)
        staging.rename(target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target
