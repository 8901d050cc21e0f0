"""Render a scheme into a C package: {filename: text} in memory, written to disk separately.

Templates are listed in one table (TEMPLATES); every decision is made here and handed to them as
a context, rendered with StrictUndefined so a missing value fails instead of printing "". The
facts of the C interface (status codes, options, entry points) come from the runtime's contract
through chaingen.generate.interface, so the header, the Python loader and the manifest agree.
"""
from __future__ import annotations

import dataclasses
import importlib.resources
import json
import os
import textwrap
from dataclasses import dataclass
from pathlib import Path

import casadi
import jinja2
import sympy

from ..errors import ChaingenError, PackageWriteError, RunFailedError, SceneError
from ..runtime import contract
from ..runtime.contract import Features
from ..runtime.files import write_directory
from ..scene import Scene, SolverSpec, c_identifier, labels
from ..scene.kinematics import RUN_SEGMENT_RELATIVE_TOLERANCE, ZERO_SEGMENT_RELATIVE_TOLERANCE
from ..symbolic.schemes import DiscreteScheme, build_scheme
from ..symbolic.schemes.base import actuated_joints
from ..version import VERSION
from .casadi_functions import chains_state, scheme_functions
from .casadi_source import model_c_sources, work_sizes
from .example import example_context
from .interface import CInterface, c_literal, dimension_macros
from .key import input_hash
from .step_constants import with_step_constants

#: template -> file it renders ({prefix} is replaced by the package prefix)
TEMPLATES = {
    "solver.h.j2": "{prefix}.h",
    "solver.c.j2": "{prefix}.c",
    "Makefile.j2": "Makefile",
    "CMakeLists.txt.j2": "CMakeLists.txt",
    "example.c.j2": "example.c",
    "README.md.j2": "README.md",
}
#: The example of a package whose step holds a control law (feature `control`), in place of
#: example.c.j2's PD controller, which would fight the law (codegen/generate/example.py).
CONTROLLED_EXAMPLE = "example_control.c.j2"
#: The runtime library (runtime/c/), copied into every package: its source, compiled into the
#: package's own (<prefix>.c includes it), and its headers.
RUNTIME_FILES = ("chaingen_runtime.c", "chaingen_runtime.h", "chaingen_contract.h",
                 "chaingen_workspace.h", "chaingen_lu.h", "chaingen_arm_solve.h")
#: The runtime headers a package's public header includes, installed beside it.
PUBLIC_RUNTIME_HEADERS = ("chaingen_contract.h", "chaingen_workspace.h")
#: Fields of the model table (chaingen_runtime.h) that point at a generated function, and the
#: function (SchemeFunctions' field) each is.
MODEL_FUNCTIONS = (
    ("parameters", "parameters"), ("initial_state", "initial_state"), ("outputs", "outputs"),
    ("holding_torques", "holding_torques"), ("residual", "residual"),
    ("residual_jacobian", "residual_jacobian"), ("newton_factors", "newton_factors"),
    ("chord_factors", "chord_factors"), ("step_constants", "step_constants"),
    ("predictor", "predictor"), ("next_state", "next_state"), ("segment_margins",
    "segment_margins"), ("energy_terms", "energy_check"), ("sensitivity_rhs", "sensitivity_rhs"),
    ("sensitivity_map", "sensitivity_map"), ("joint_maps", "joint_maps"),
    ("newton_matrix", "newton_matrix"), ("applied_torques", "applied_torques"))

#: A model source larger than this gets LARGE_MODEL_FLAGS (gcc's -O2 time grows faster than the
#: file): vi's 2.7 MB at n = 100 take 70.1 s at -O2, 29.6 s at -O1; its 1.3 MB at n = 50 21.1
#: against 15.7 s, and -O2 makes the step 0.886 of -O1's (CHANGELOG; was 1 MB).
LARGE_MODEL_BYTES = 1_500_000
LARGE_MODEL_FLAGS = ("-O1",)
#: The solver source (Newton loop and the dense LU inlined in it) is compiled with -O3: gcc
#: vectorises the LU's column updates only there, which halves the factorisation at n = 20
#: (60 unknowns) and is neutral at n = 3 (docs/benchmarks.md).
SOLVER_FLAGS = ("-O3",)
#: Stages of generate_package that report progress (a build adds one: compiling).
GENERATE_STAGES = 3


@dataclass(frozen=True)
class GeneratedPackage:
    """A generated C package: its prefix, its files, and the manifest the runtime reads."""

    prefix: str
    files: dict[str, str]
    manifest: dict

    @property
    def sources(self) -> tuple[str, ...]:
        return tuple(name for name in sorted(self.files) if name.endswith(".c"))


def model_c_bytes(package: GeneratedPackage) -> int:
    """Bytes of the package's generated model C, all its sources (model_c_sources)."""
    return sum(len(package.files[name].encode()) for name in package.manifest["sources"][1:])


def c_list(values) -> str:
    """Integers as the body of a C array initialiser, wrapped within the generated width."""
    return textwrap.fill(", ".join(map(str, values)), width=96, subsequent_indent="    ",
                         break_on_hyphens=False)


def package_prefix(scene: Scene, method: str) -> str:
    """C prefix of every exported symbol: the scene's C name and the method. SceneError for a
    name longer than the scene format allows (a Scene made in Python, not read from a file)."""
    if len(scene.name) > contract.MAX_SCENE_NAME_LENGTH:
        raise SceneError(f"name: must be at most {contract.MAX_SCENE_NAME_LENGTH} characters "
                         f"long (it prefixes generated C and file names), not "
                         f"{len(scene.name)}")
    return f"{c_identifier(scene.name)}_{method}"


def parameter_bounds(paths) -> list[tuple[str, str, str]]:
    """(C lower bound, C inclusive flag, rule for people) of each run-time parameter: the scene
    format's bound (contract.NUMBER_BOUNDS); none: -DBL_MAX, inclusive (any finite value)."""
    bounds = []
    for path in paths:
        bound = contract.lower_bound(path)
        bounds.append(("-DBL_MAX", "1", "any finite value") if bound is None else
                      (c_literal(bound.value), str(int(bound.inclusive)), bound.rule))
    return bounds


def template_environment() -> jinja2.Environment:
    """The Jinja2 environment of the templates (package data chaingen.templates)."""
    loader = jinja2.FunctionLoader(
        lambda name: importlib.resources.files("chaingen.templates").joinpath(name).read_text())
    return jinja2.Environment(loader=loader, undefined=jinja2.StrictUndefined,
                              keep_trailing_newline=True, autoescape=False)


def scheme_label(scheme: DiscreteScheme) -> str:
    """The scheme as a package's banner and header name it (chaingen.scene.labels)."""
    return labels.scheme_label(scheme.method, scheme.quadrature, scheme.order, style="header",
                               quadrature_rule=scheme.quadrature_rule,
                               composition_steps=len(scheme.composition),
                               gradient=getattr(scheme, "gradient", None))


def package_features(scheme: DiscreteScheme, sensitivities: bool) -> Features:
    return Features(inputs=bool(scheme.inputs.shape[0]), flows=scheme.has_energy_flows,
                    sensitivities=sensitivities, segments=bool(scheme.segment_tolerances),
                    parameters=bool(scheme.parameter_paths),
                    energy_check=scheme.kinetic_energy is not None,
                    # a composed step has no single z to evaluate them at (UNAVAILABLE)
                    control=(scheme.flows.applied_torques is not None
                             and len(scheme.composition) == 1))


def newton_defaults(scheme: DiscreteScheme) -> dict:
    """The package's Newton defaults: the contract's, with the scheme's Jacobian reuse and
    overrides."""
    return {**contract.NEWTON_OPTION_DEFAULTS, "reuse_jacobian": scheme.jacobian_reuse,
            **dict(scheme.newton_overrides)}


def comment_text(text: str) -> str:
    """Text for the inside of a C block comment: wrapped at the generated width, each line after
    the first starting " * "."""
    return "\n * ".join(textwrap.wrap(text, width=96))


def _c_array(c_type: str, name: str, values) -> str:
    """A static const C array, its initialiser wrapped within the generated width."""
    return f"static const {c_type} {name}[{len(values)}] = {{\n    {c_list(values)}\n}};\n"


def model_table(scheme: DiscreteScheme, functions, sizes: dict,
                defaults: dict) -> tuple[str, str]:
    """The package's model table (chaingen_runtime.h's chaingen_model) as C: the static arrays
    it points at, and its field initialisers."""
    tables = []
    stages = [c_literal(f) for f in scheme.composition] if len(scheme.composition) > 1 else []
    if stages:
        tables.append("/* The stages of the composed step: fractions of dt that sum to 1. */\n"
                      + _c_array("double", "STAGES", stages))
    bounds = parameter_bounds(scheme.parameter_paths)
    if bounds:
        tables.append("/* The lower bound of each parameter, the scene format's (chaingen's "
                      "contract,\n * NUMBER_BOUNDS), and whether p_i may equal it; -DBL_MAX, "
                      "inclusive: any finite value. */\n"
                      + _c_array("double", "P_LOWER", [b[0] for b in bounds])
                      + _c_array("int", "P_INCLUSIVE", [b[1] for b in bounds]))
    if functions.arm_pattern:
        tables.append("/* The structural nonzeros of H = dh/dw (chaingen_arm_solve.h), on the "
                      "arms: row, column. */\n"
                      + _c_array("int", "ARM_H_ROW", functions.arm_pattern[0])
                      + _c_array("int", "ARM_H_COL", functions.arm_pattern[1]))
    options = ", ".join(c_literal(defaults[field.name]) for field in contract.NEWTON_OPTIONS)
    fields = dict(sizes)
    fields.update({
        "stages": "STAGES" if stages else "NULL",
        # A start state's segments are measured against the scene reader's tolerance: in
        # margins (length / RUN_SEGMENT_RELATIVE_TOLERANCE G), at least this.
        "start_margin": f"{ZERO_SEGMENT_RELATIVE_TOLERANCE!r} / "
                        f"{RUN_SEGMENT_RELATIVE_TOLERANCE!r}",
        "p_lower": "P_LOWER" if bounds else "NULL",
        "p_inclusive": "P_INCLUSIVE" if bounds else "NULL",
        "arm_h_row": "ARM_H_ROW" if functions.arm_pattern else "NULL",
        "arm_h_col": "ARM_H_COL" if functions.arm_pattern else "NULL",
        "defaults": f"{{{options}}}",
    })
    dense = functions.newton_factors is None
    for field, attribute in MODEL_FUNCTIONS:
        function = getattr(functions, attribute)
        if attribute == "residual_jacobian" and not dense:
            function = None   # formed from the factors (chaingen_arm_solve.h)
        fields[field] = "NULL" if function is None else function.name()
    lines = [f"    .{name} = {value}," for name, value in fields.items()]
    return "\n".join(tables), "\n".join(lines)


def layout_comments(scheme: DiscreteScheme, prefix: str, columns, parameters) -> str:
    """The header's comments on the layouts of x, u, p, z, a sample row and the energy flows."""
    P = prefix.upper()
    scene = scheme.scene

    def listing(title: str, entries) -> str:
        return "\n".join([f"/* {title}"] + [f" *   {entry}" for entry in entries]) + " */\n"

    parts = [listing(f"State x ({P}_NX entries): {scheme.state_layout.description}.",
                     [f"x[{i}] {name}" for i, name in enumerate(scheme.state_layout.entries)])]
    if actuated_joints(scene):
        parts.append(listing(
            f"Inputs u ({P}_NU entries): the torque (N m) of each actuated joint, held constant "
            "over a\n * step. It acts between link i-1 and link i, positive in the direction of "
            "phi_i (power tau phidot).",
            [f"u[{i}] tau of joint {joint}" for i, joint in enumerate(actuated_joints(scene))]))
    else:
        parts.append("/* The scene has no [actuation] table: the chain is unactuated, NU is 0 "
                     "and u is NULL. */\n")
    if parameters:
        parts.append(listing(
            f"Parameters p ({P}_NP entries): numbers of the scene the solver takes at run time, "
            "by their\n * key path in the scene file (unit; the scene's own value; the values "
            "the scene format allows).\n * Every other number of the scene is a constant of the "
            "code.",
            [f"p[{i}] {path} ({unit}; {value}; {rule})"
             for i, (path, unit, value, rule) in enumerate(parameters)]))
    else:
        parts.append("/* The package takes no run-time parameters: NP is 0 and p is NULL. */\n")
    parts.append(listing(
        f"Newton unknowns z ({P}_NZ entries): {scheme.unknowns_layout.description}.",
        [f"z[{i}] {name}" for i, name in enumerate(scheme.unknowns_layout.entries)])[:-4]
        + f"\n * Residual F (same length): {scheme.residual_description}. */\n")
    parts.append(listing(f"One sample row of simulate ({P}_NSAMPLE entries), the columns of the "
                         "trajectory file:",
                         [f"[{i}] {name}: {meaning}" for i, (name, meaning)
                          in enumerate(columns)]))
    flows = scheme.flow_description
    if flows:
        parts.append(f"/* Energy flows of one step (flows[2]): flows[0] the work of the joint "
                     f"torques {flows.input_work},\n * flows[1] the energy dissipated by joint "
                     f"damping {flows.dissipated}, >= 0 (J).\n * {flows.balance} */\n")
    else:
        parts.append("/* Energy flows of one step (flows[2]): the scene has neither actuated nor "
                     "damped joints, and\n * they are zero: the energy is conserved. */\n")
    return "\n".join(parts)


def render_package(scheme: DiscreteScheme, *, sensitivities: bool = True,
                   progress=None) -> GeneratedPackage:
    """The C package of `scheme`: CasADi code for its functions and the templates around it.

    sensitivities=False leaves out the generated functions of step_sensitivities (a package
    only run forward, as `chaingen simulate` does, builds faster without them; its
    step_sensitivities returns UNAVAILABLE). progress: told of each stage,
    progress(stage, note) (chaingen.progress: a Progress is one).
    """
    scene = scheme.scene
    prefix = package_prefix(scene, scheme.method)
    digest = input_hash(scene, scheme.method, scheme.quadrature, sensitivities,
                        scheme.parameter_paths, scheme.order, scheme.gradient)
    if progress is not None:
        progress(1, "CasADi functions and derivatives")
    functions = with_step_constants(scheme_functions(scheme, prefix,
                                                     sensitivities=sensitivities), prefix)
    ny = functions.step_constants.size1_out(0) if functions.step_constants else 0
    if progress is not None:
        progress(2, "C code of the model")
    model_sources, model_header = model_c_sources(functions, prefix)
    work = {key: max(1, value) for key, value in dataclasses.asdict(
        work_sizes(functions.all())).items()}
    work["w"] += ny   # the step's constants y lead the real work array (chaingen_runtime.c)
    source_flags = {f"{prefix}.c": list(SOLVER_FLAGS), **{name: list(LARGE_MODEL_FLAGS) for
                    name, text in model_sources.items() if len(text) > LARGE_MODEL_BYTES}}
    model_flags = LARGE_MODEL_FLAGS if len(source_flags) > 1 else ()
    defaults = newton_defaults(scheme)
    features = package_features(scheme, sensitivities)
    interface = CInterface(prefix)
    segment_tolerance = f"{scheme.segment_relative_tolerance:g}"

    banner_text = (f"Generated by chaingen {VERSION} (SymPy {sympy.__version__}, CasADi "
                   f"{casadi.__version__}) for scene \"{scene.name}\", {scheme_label(scheme)}. "
                   f"Do not edit. chaingen_input_hash={digest}")
    c_banner = f"/* {banner_text} */"
    n = scene.n
    nu = len(actuated_joints(scene))
    n_p = len(scheme.parameter_paths)
    columns = contract.sample_columns(n, features.flows)
    chain_state = chains_state(scheme)
    nstage = len(scheme.composition) if len(scheme.composition) > 1 else 0
    sizes = {
        "n_joints": n, "nx": len(scheme.state_layout), "nz": len(scheme.unknowns_layout),
        "nu": nu, "np": n_p, "held_control": int(scheme.control_law == "sampled"),
        "nq": functions.parameters.size1_out(0) if functions.parameters is not None else 0,
        "nsample": len(columns), "nconstraint": scheme.constraint_residuals.shape[0],
        "nsegment": len(scheme.segment_tolerances), "order": scheme.order, "nstage": nstage,
        # The adaptive steps' error test: es's nodal rates at order 2 are off C(q) v = 0 by
        # O(dt^2) in every step without accumulating (model.md 14), which step
        # doubling would take for the local error; there the test takes the angles alone.
        "error_entries": n if scheme.method == "es" and scheme.order == 2 else 2 * n,
        "flows": int(features.flows), "energy_check": int(features.energy_check),
        "sensitivities": int(sensitivities), "chain_state": int(chain_state),
        "arm_nh": len(functions.arm_pattern[0]) if functions.arm_pattern else 0, "ny": ny,
    }
    tables, model_fields = model_table(scheme, functions, sizes, defaults)
    parameters_listed = list(zip(scheme.parameter_paths, scheme.parameter_units,
                                 map(c_literal, scheme.parameter_values),
                                 [rule for _, _, rule in parameter_bounds(scheme.parameter_paths)]))
    context = {
        "banner": c_banner, "make_banner": f"# {banner_text}", "banner_text": banner_text,
        "prefix": prefix, "PREFIX": prefix.upper(),
        "scene_name": scene.name, "method": scheme.method,
        "scheme_label": scheme_label(scheme), "method_summary": scheme.summary,
        "nu": nu, "np": n_p, "nstage": nstage,
        # The rest of chaingen_workspace.h's formula: NQ, NSTAGE, ARM_NH, SENSITIVITIES,
        # CHAIN_STATE, NSEGMENT, NCONSTRAINT.
        "workspace_sizes": ", ".join(str(sizes[key]) for key in (
            "nq", "nstage", "arm_nh", "sensitivities", "chain_state", "nsegment",
            "nconstraint")),
        "n": n, "nx": sizes["nx"], "nz": sizes["nz"], "nsample": sizes["nsample"],
        "flows": int(features.flows),
        "p_arguments": f"parameters, {prefix.upper()}_NP" if n_p else "NULL, 0",
        "actuated_joints": actuated_joints(scene),
        # A law without a [control] table (a stand-in a test puts into a scheme) has no target
        # of its own: the example's posture is then the PD example's.
        **example_context(scene, controlled=features.control
                          and getattr(scene, "control", None) is not None),
        "parameters": parameters_listed,
        "work": work,
        "defaults": {name: c_literal(value) for name, value in defaults.items()},
        "status_macros": interface.status_macros(segment_tolerance),
        "jacobian_mode_macros": interface.jacobian_mode_macros(),
        "dimension_macros": dimension_macros(prefix),
        "prototypes": {entry.name: interface.prototype(entry.name)
                       for entry in contract.ENTRY_POINTS},
        "wrappers": [interface.wrapper(entry.name) for entry in contract.ENTRY_POINTS],
        "tables": tables, "model_fields": model_fields,
        "layouts": layout_comments(scheme, prefix, columns, parameters_listed),
        "defaults_text": comment_text(", ".join(f"{name} {c_literal(value)}"
                                                for name, value in defaults.items())),
        "step_text": comment_text(
            f"The step is of order {scheme.order}: a symmetric composition of {nstage} steps "
            "of the scheme, of dt times " + ", ".join(map(c_literal, scheme.composition))
            + " (one negative: a step back in time); each stage keeps the scheme's structure."
            if nstage else "The scheme's step, of order 2."),
        "sensitivities_text": comment_text(
            "This package has them." if sensitivities else
            "This package was generated without them (chaingen generate --no-sensitivities): "
            f"{prefix.upper()}_UNAVAILABLE."),
        "control_text": comment_text(
            "The embedded controller's step: the step step() takes from x0 (the same checks, "
            "warm start, Newton and workspace history: from the same workspace, x1 and "
            "iterations are bitwise step()'s), and tau[NU], the torque each actuated joint "
            "applies over it (in u's order, N m), which the scheme's control law determines "
            "inside the step's Newton system: evaluated at the step's converged unknowns z. A "
            "step that step() would take as halves (the fallback ladder's last rung) has no "
            "single torque over dt: the whole step's status (NOT_CONVERGED, SINGULAR_JACOBIAN, "
            "NONFINITE, SEGMENT_COLLAPSED or ENERGY_JUMP), and neither tau nor x1 is written "
            "(nor on any other failure; iterations is, as by step()). Arguments as step() "
            "(BAD_ARGUMENT also for a NULL tau or an x0 with NaN or Inf); one workspace a thread. "
            + ("This package's scheme has a control law." if features.control else
               "This package's scheme has no control law (or its step is composed): "
               f"{prefix.upper()}_UNAVAILABLE.")),
        "max_split": contract.MAX_SPLIT_DEPTH,
        "refresh_rate": c_literal(contract.REFRESH_RATE),
        "simplified_margin": c_literal(contract.SIMPLIFIED_MARGIN),
        "chord_margin": c_literal(contract.CHORD_MARGIN),
        "source_flags": {name: " ".join(flags) for name, flags in source_flags.items()},
        "model_flags": " ".join(model_flags), "large_model_bytes": LARGE_MODEL_BYTES,
        "sources": [f"{prefix}.c", *model_sources],
        "strict_flags": " ".join(contract.STRICT_FLAGS),
        "public_headers": [f"{prefix}.h", *PUBLIC_RUNTIME_HEADERS],
    }
    environment = template_environment()
    files = {output.format(prefix=prefix): environment.get_template(
        CONTROLLED_EXAMPLE if features.control and template == "example.c.j2" else template
    ).render(context) for template, output in TEMPLATES.items()}
    files.update({name: f"{c_banner}\n{text}" for name, text in model_sources.items()})
    files[f"{prefix}_model.h"] = f"{c_banner}\n{model_header}"
    for name in RUNTIME_FILES:
        files[name] = importlib.resources.files("chaingen.runtime").joinpath("c", name).read_text()
    manifest = {
        "chaingen_version": VERSION, "input_hash": digest, "prefix": prefix,
        "scene": scene.name, "method": scheme.method, "quadrature": scheme.quadrature,
        "gradient": scheme.gradient, "order": scheme.order, "composition": list(scheme.composition),
        "n_joints": n, "nx": context["nx"], "nz": context["nz"], "nsample": context["nsample"],
        "actuated_joints": list(actuated_joints(scene)), "nu": nu,
        "parameters": [{"path": path, "unit": unit, "value": value,
                        "lower": None if bound is None else bound.value,
                        "lower_inclusive": True if bound is None else bound.inclusive}
                       for path, unit, value, bound
                       in zip(scheme.parameter_paths, scheme.parameter_units,
                              scheme.parameter_values,
                              map(contract.lower_bound, scheme.parameter_paths))],
        "energy_flows": features.flows, "sensitivities": sensitivities,
        "segment_tolerance": scheme.segment_relative_tolerance if features.segments else None,
        "energy_check": features.energy_check,
        "control": features.control, "control_law": scheme.control_law,
        "state": list(scheme.state_layout.entries),
        "unknowns": list(scheme.unknowns_layout.entries),
        "sample_columns": [name for name, _ in columns],
        "files": sorted(files) + [contract.MANIFEST],
        "sources": context["sources"],
        "source_flags": source_flags,
        "newton_defaults": defaults,
        "entry_points": contract.manifest_entry_points(prefix, features),
    }
    files[contract.MANIFEST] = json.dumps(manifest, indent=2) + "\n"
    return GeneratedPackage(prefix=prefix, files=dict(sorted(files.items())), manifest=manifest)


def generate_package(scene: Scene | SolverSpec, method: str | None = None,
                     quadrature: int | None = None, *, sensitivities: bool = True,
                     parameters=(), order: int = 2, gradient: str = "exact",
                     progress=None) -> GeneratedPackage:
    """SolverSpec -> scheme -> C package, all in memory; or of `scene` with the keywords a
    SolverSpec is made of. parameters: key paths of the scene's numbers the solver takes at
    run time; order: 2 (the scheme's step), 4 or 6 (composed); gradient: es's discrete
    gradient of the springs ("exact", "quadrature" or "chain"). progress: see render_package."""
    spec = scene if isinstance(scene, SolverSpec) else SolverSpec(
        scene, method, quadrature, order=order, parameters=parameters,
        sensitivities=sensitivities, gradient=gradient)
    package_prefix(spec.scene, spec.method)   # a name too long for C fails before SymPy
    if progress is not None:
        progress(0, "deriving the model and the scheme (SymPy)")
    package = render_package(build_scheme(spec), sensitivities=spec.sensitivities,
                             progress=progress)
    if progress is not None:
        progress(GENERATE_STAGES)
    return package


def check_package_target(directory: str | os.PathLike) -> Path:
    """The directory a package may be written to, or PackageWriteError saying why not: an
    existing directory is replaced only if it is a chaingen package (has a manifest) or empty,
    so a typo in -o cannot wipe unrelated files. Checked before generating, and again when
    writing."""
    target = Path(directory)
    if target.exists():
        if not target.is_dir():
            raise PackageWriteError(f"{target}: exists and is not a directory")
        if any(target.iterdir()) and not (target / contract.MANIFEST).is_file():
            raise PackageWriteError(
                f"{target}: exists and is not a chaingen package (no {contract.MANIFEST}); "
                "choose an empty or new directory")
    ancestor = target.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise PackageWriteError(f"{target}: {ancestor} is not a directory")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise PackageWriteError(f"{target}: directory {ancestor} is not writable")
    return target


def write_package(package: GeneratedPackage, directory: str | os.PathLike) -> Path:
    """Write the package's files into `directory`, where check_package_target allows it.
    A new or empty directory is written all or nothing (chaingen.runtime.files). An existing
    package is updated: the files its manifest lists are replaced or, if the new package has
    them no longer, removed, the manifest last; every other file (a user's source, the
    build/ of its README's CMake commands) is kept, and a file of the new package whose name
    such a file takes is refused (PackageWriteError, nothing written). A write that fails (a
    full disk) is RunFailedError, exit status 1, leaving the old files."""
    target = check_package_target(directory)
    try:
        return write_directory(target, package.files, written_before=_written_before,
                               last=contract.MANIFEST)
    except ChaingenError as error:
        raise PackageWriteError(str(error)) from None
    except OSError as error:
        raise RunFailedError(f"{target}: cannot write the package: "
                             f"{error.strerror or error}; nothing written") from None


def _written_before(directory: Path) -> set[str]:
    """The files an earlier write of a package put in `directory`: those its manifest lists
    (plain names only), and the manifest itself."""
    names = {contract.MANIFEST}
    try:
        listed = json.loads((directory / contract.MANIFEST).read_text()).get("files", [])
    except (OSError, ValueError, AttributeError):
        return names
    if isinstance(listed, list):
        names.update(name for name in listed
                     if isinstance(name, str) and name == Path(name).name)
    return names
