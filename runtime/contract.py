"""The C interface of a generated package, stated once.

Every fact a generated package shares with the code around it is written here and nowhere else:
status codes and their messages, the Newton option fields with their defaults, the
Jacobian-reuse modes, the depth of the warm-start history, the counters of a run, the columns of
a sample row, and the parameter list of every exported C entry point. The generator renders the
runtime's contract header and each package's macros and prototypes from these tables, and the
Python loader declares its ctypes signatures from the same table. Every package has every entry
point with the same signature; one that needs a feature the package lacks returns UNAVAILABLE.
The features a package may have:

- ``inputs``: the scene has actuated joints (torques u);
- ``flows``: energy can enter or leave the chain (actuation or joint damping);
- ``sensitivities``: the package was generated with the step sensitivities;
- ``segments``: the scene has springs, whose segments are watched for collapse;
- ``parameters``: the package takes some of the scene's numbers as run-time parameters p;
- ``energy_check``: a converged step is checked against the energy balance, which the step does
  not keep exactly (vi, midpoint) or at a spurious root (spatial es; docs/model.md 13, 4.8);
- ``control``: a control law solved inside the step sets the actuated joints' torques (issue 34).

This module is plain data: it imports nothing of chaingen and nothing beyond the standard library.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

#: The features an entry point, a parameter or a status may depend on.
FEATURES = ("inputs", "flows", "sensitivities", "segments", "parameters", "energy_check", "control")


@dataclass(frozen=True)
class Features:
    """Which optional parts a package has (see the module docstring)."""

    inputs: bool = False
    flows: bool = False
    sensitivities: bool = False
    segments: bool = False
    parameters: bool = False
    energy_check: bool = False
    control: bool = False

    @classmethod
    def from_manifest(cls, manifest: dict) -> Features:
        """The features a package's manifest records."""
        return cls(inputs=bool(manifest["nu"]), flows=bool(manifest["energy_flows"]),
                   sensitivities=bool(manifest["sensitivities"]),
                   segments=manifest["segment_tolerance"] is not None,
                   energy_check=bool(manifest["energy_check"]),
                   parameters=bool(manifest["parameters"]), control=bool(manifest.get("control")))

    def has(self, when: str | None) -> bool:
        """Whether something present `when` a feature is there (None: always)."""
        if when is None:
            return True
        if when not in FEATURES:
            raise ValueError(f"unknown feature {when!r} (known: {', '.join(FEATURES)})")
        return bool(getattr(self, when))


# --- Status codes --------------------------------------------------------------------------

@dataclass(frozen=True)
class Status:
    """A status code: the header's <PREFIX>_<name>, what it means to a reader of the header,
    and the message a person gets from the Python runtime."""

    name: str
    code: int
    comment: str
    message: str


#: Adaptive steps: the shortest step tried, as a fraction of the sample interval dt; a step
#: that fails below it stops the run (STEP_TOO_SMALL).
MIN_STEP_FRACTION = 1e-12

STATUSES = (
    Status("OK", 0, "success", "success"),
    Status("NOT_CONVERGED", 1, "Newton: max_iterations reached without convergence",
           "Newton's method did not converge within max_iterations"),
    Status("SINGULAR_JACOBIAN", 2, "Newton: no usable pivot in the LU factorisation",
           "the Newton Jacobian is singular (no usable pivot)"),
    Status("NONFINITE", 3, "NaN or Inf in the residual or the iterate",
           "NaN or Inf in the residual or the Newton iterate"),
    Status("BAD_ARGUMENT", 4, "a null pointer, dt <= 0 or not finite, a NaN or Inf in a state, "
                              "posture or input u, n_steps < 0, every < 1, interval < 1, hold < 1, "
                              "more sample rows than memory can address, an unknown "
                              "reuse_jacobian or a bad rtol, atol or energy_tol",
           "bad argument"),
    Status("EVALUATION_FAILED", 5, "a generated function reported an error",
           "a generated function reported an evaluation error"),
    Status("SEGMENT_COLLAPSED", 6,
           "a spring segment came within {segment_tolerance} of the geometry's size of zero "
           "length, or passed through it (turned by 90 degrees or more in one step), or a "
           "start state or posture has one of zero length (under 1e-9 of that size, the scene "
           "reader's limit): its direction is undefined there (docs/model.md, section 2)",
           "a spring segment came within {segment_tolerance} of the geometry's size of zero "
           "length or passed through it (turned by 90 degrees or more in one step), or one is "
           "shorter than 1e-9 of that size in the start state or posture given, where its "
           "direction is undefined"),
    Status("INTERRUPTED", 7, "simulate_observed or simulate_controlled: the observer, the "
                             "controller or control->stop asked to stop",
           "interrupted"),
    Status("STEP_TOO_SMALL", 8, "adaptive steps: the error test or Newton failed at a step "
                                f"below {MIN_STEP_FRACTION:g} dt",
           f"the adaptive step fell below {MIN_STEP_FRACTION:g} of the sample interval dt "
           "without passing the error test and Newton"),
    Status("ENERGY_JUMP", 9,
           "the converged step missed the energy balance by more than energy_tol times the "
           "kinetic energy at its ends: a spurious root of a step too long for the motion",
           "the converged step missed the energy balance by more than energy_tol times its "
           "kinetic energy (a spurious Newton root of a step too long for the motion)"),
    Status("BAD_PARAMETER", 10, "a run-time parameter p_i is not finite or below its lower "
                                "bound, a value the scene format refuses (see p above)",
           "a run-time parameter is not finite or below its lower bound (a value the scene "
           "format refuses)"),
    Status("UNAVAILABLE", 11, "the package was generated without this function: step_sensitivities "
                              "without the sensitivities, holding_torques and simulate_controlled "
                              "without actuated joints, control_torques without a control law",
           "the package was generated without this function"),
)
STATUS_CODES = {status.name: status.code for status in STATUSES}


def status_message(code: int, segment_tolerance: float | None = None) -> str:
    """The message of a status code for people (the code itself if it is unknown)."""
    for status in STATUSES:
        if status.code == code:
            tolerance = "its tolerance" if segment_tolerance is None else f"{segment_tolerance:g}"
            return status.message.format(segment_tolerance=tolerance)
    return f"unknown status {code}"


# --- Ranges of the scene's numbers ---------------------------------------------------------

@dataclass(frozen=True)
class LowerBound:
    """The least value a number of a scene may take: `value` itself too when `inclusive`."""

    value: float
    inclusive: bool

    def admits(self, number: float) -> bool:
        """Whether `number` is within the bound (NaN never is)."""
        return number >= self.value if self.inclusive else number > self.value

    @property
    def rule(self) -> str:
        """'>= 0', '> 0': the bound as the scene reader's messages say it."""
        return f"{'>=' if self.inclusive else '>'} {self.value:g}"


#: The lower bounds of a scene's numbers, by the last key of their key path (links[1].mass:
#: "mass"), stated once: the scene reader refuses a number below its bound
#: (docs/scene-format.md), a package's C refuses a run-time parameter below it (status
#: BAD_PARAMETER), and the manifest records it for the Python runtime. A number not named here
#: (com, com_normal, fastening, offsets, angles, velocities) may be any finite value.
NUMBER_BOUNDS = {
    "gravity": LowerBound(0.0, True),
    "mass": LowerBound(0.0, False),
    "inertia": LowerBound(0.0, True),
    "length": LowerBound(0.0, False),
    "damping": LowerBound(0.0, True),
    "stiffness": LowerBound(0.0, False),
    "rest_length": LowerBound(0.0, True),
    "dt": LowerBound(0.0, False),
    "t_end": LowerBound(0.0, False),
}


def lower_bound(path: str) -> LowerBound | None:
    """The bound of the number at `path` (NUMBER_BOUNDS); None if none (spatial gravity[j])."""
    return None if path.startswith("gravity[") else NUMBER_BOUNDS.get(
        re.sub(r"\[[0-9]+\]", "", path).rsplit(".", 1)[-1])


#: The longest scene name: it prefixes every exported C name and the names of a package's files
#: and of its libraries in the build cache (lib<name>_<method>-<hash>.so.json), which must stay
#: within the 255 bytes file systems allow.
MAX_SCENE_NAME_LENGTH = 128


# --- Newton options ------------------------------------------------------------------------

@dataclass(frozen=True)
class JacobianMode:
    """A value of the option reuse_jacobian: when dF/dz is evaluated and factorised."""

    name: str
    value: int
    comment: str


JACOBIAN_MODES = (
    JacobianMode("JACOBIAN_EVERY_ITERATE", 0, "full Newton"),
    JacobianMode("JACOBIAN_ACROSS_STEPS", 1, "simplified Newton"),
    JacobianMode("JACOBIAN_PER_STEP", 2, "Newton-chord: once a step"),
    JacobianMode("JACOBIAN_CHORD_ACROSS_STEPS", 3, "Newton-chord, kept across chained steps"),
)
(JACOBIAN_EVERY_ITERATE, JACOBIAN_ACROSS_STEPS, JACOBIAN_PER_STEP,
 JACOBIAN_CHORD_ACROSS_STEPS) = (mode.value for mode in JACOBIAN_MODES)


@dataclass(frozen=True)
class OptionField:
    """An options field: C type, default, header comment, switch (0/1), least value."""

    name: str
    c_type: str
    default: int | float
    comment: str = ""
    switch: bool = False
    lower: LowerBound | None = None

    @property
    def python_type(self) -> type:
        return bool if self.switch else int if self.c_type == "int" else float


#: The energy check's default (docs/model.md, section 13): a converged step of vi or midpoint
#: whose energy balance misses by more than this times the kinetic energy at its ends is a
#: spurious root, refused and split.
DEFAULT_ENERGY_TOL = 0.01

NEWTON_OPTIONS = (
    OptionField("max_iterations", "int", 20, "bounds the work of one step",
                lower=LowerBound(1, True)),
    OptionField("update_rtol", "double", 1e-10, lower=LowerBound(0.0, True)),
    OptionField("update_atol", "double", 1e-13, lower=LowerBound(0.0, False)),
    OptionField("residual_tol", "double", 1e-8, "units of F", lower=LowerBound(0.0, False)),
    OptionField("warm_start", "int", 1, "continue from the previous solutions", switch=True),
    OptionField("reuse_jacobian", "int", JACOBIAN_EVERY_ITERATE, "one of the JACOBIAN_* modes"),
    OptionField("energy_tol", "double", DEFAULT_ENERGY_TOL,
                "vi, midpoint, spatial es: a step with |H_1 - H_0 - W + D| > energy_tol "
                "(T_0 + T_1) is refused and split; 0: no check", lower=LowerBound(0.0, True)),
    OptionField("rtol", "double", 0.0, "adaptive steps: relative local error, 0 or >= 1e-14; 0 "
                                       "with atol 0: fixed steps of dt"),
    OptionField("atol", "double", 0.0, "adaptive steps: absolute local error (rad, rad/s), 0 "
                                       "or >= 1e-14"),
)
NEWTON_OPTION_DEFAULTS = {field.name: field.default for field in NEWTON_OPTIONS}
#: The adaptive steps' tolerances rtol and atol are 0 (off) or at least this: the error
#: estimate of a step is round-off below it, and a tolerance there would be met only by
#: chance, at steps ever shorter.
MIN_ADAPTIVE_TOLERANCE = 1e-14
ADAPTIVE_TOLERANCES = ("rtol", "atol")
#: What rtol and atol may be, as error messages say it.
ADAPTIVE_TOLERANCE_RULE = f"0 (fixed steps) or from {MIN_ADAPTIVE_TOLERANCE:g} up, and finite"


def is_adaptive_tolerance(value: float) -> bool:
    """Whether `value` may be an rtol or atol (ADAPTIVE_TOLERANCE_RULE)."""
    return value == 0 or MIN_ADAPTIVE_TOLERANCE <= value < float("inf")

#: Solutions of chained steps kept for the warm start: extrapolation of degree
#: WARM_START_HISTORY - 1 (quadratic).
WARM_START_HISTORY = 3
#: A kept Jacobian (simplified Newton, Newton-chord) is evaluated anew when successive updates
#: shrink by less than this.
REFRESH_RATE = 0.1
#: A kept Jacobian stops when its estimated error is this fraction of the tolerance: simplified
#: Newton (a speed option) at 0.1, Newton-chord (which stands in for full Newton and must keep
#: its round-off energy balance) at 1e-3.
SIMPLIFIED_MARGIN = 0.1
CHORD_MARGIN = 1e-3


# --- Counters of a run, and the sample row -------------------------------------------------

@dataclass(frozen=True)
class StructField:
    name: str
    c_type: str
    comment: str


STATS_FIELDS = (
    StructField("steps", "long", "steps completed (the failing one excluded)"),
    StructField("newton_iterations", "long",
                "Newton iterations (linear solves) over all completed steps"),
    StructField("max_newton_iterations", "int", "the most a single completed step took"),
    StructField("failed_iterations", "int", "iterations spent in the failing step, 0 if none "
                                            "failed"),
    StructField("full_newton_fallbacks", "long", "steps whose kept Jacobian failed and that "
                                                 "full Newton solved"),
    StructField("split_steps", "long", "steps that Newton failed on whole and that were "
                                       "taken as two halves (recursively)"),
    StructField("accepted_steps", "long", "steps of the scheme taken: steps with fixed steps; "
                                          "adaptive: the accepted ones"),
    StructField("rejected_steps", "long", "adaptive: steps refused by the error test or Newton"),
    StructField("smallest_dt", "double", "the shortest accepted step (s)"),
    StructField("largest_dt", "double", "the longest accepted step (s)"),
)

#: What a caller shares with a running simulate_observed, from another thread or a signal
#: handler: a request to stop, and the steps completed so far.
CONTROL_FIELDS = (
    StructField("stop", "volatile int", "set nonzero to stop the run after the current step "
                                        "(status INTERRUPTED)"),
    StructField("steps", "volatile long", "steps completed so far, written after every step"),
)
#: The fallback ladder of a step that fails: the kept Jacobian, then full Newton from the
#: predictor, then the step split into halves, at most this many times in a row (2^depth substeps).
MAX_SPLIT_DEPTH = 4

#: Energy flows of one step (flows[2]): the work of the joint torques, then the energy
#: dissipated by joint damping.
FLOW_ENTRIES = ("input_work", "dissipated")


@dataclass(frozen=True)
class SampleColumn:
    """An entry of a sample row of simulate, which is also a column of the trajectory file
    (docs/scene-format.md): its name (with "{i}": one column per joint i = 1..n, named
    phi1 .. phin), its meaning, its unit ("": none), and whether only a package with the
    feature `flows` writes it."""

    name: str
    meaning: str
    unit: str
    flows: bool = False

    @property
    def per_joint(self) -> bool:
        return "{i}" in self.name

    def names(self, n: int) -> tuple[str, ...]:
        """The names of its columns in a row of a chain of n joints."""
        return tuple(self.name.format(i=i) for i in range(1, n + 1)) if self.per_joint else (
            self.name,)

    def described(self, i: int | None = None) -> str:
        """Its meaning with the unit, as the header's comments give it."""
        meaning = self.meaning.format(i=i) if self.per_joint else self.meaning
        return f"{meaning} ({self.unit})" if self.unit else meaning


#: The sample row, in order. A scene with energy flows adds them (FLOW_ENTRIES), cumulative
#: since the start, so that H - H_0 = input_work - dissipated can be read off every row
#: (docs/model.md, section 7). The C writer, the trajectory file, SimulationResult and
#: `chaingen plot` read the row by this table (chaingen.runtime.results.sample_slice).
SAMPLE_COLUMNS = (
    SampleColumn("t", "time", "s"),
    SampleColumn("phi{i}", "relative angle of joint {i}, wrapped to (-pi, pi]", "rad"),
    SampleColumn("omega{i}", "relative angular velocity of joint {i}", "rad/s"),
    SampleColumn("energy", "H = T + V", "J"),
    SampleColumn("constraint_error", "largest structural error of the state's coordinates", ""),
    SampleColumn(FLOW_ENTRIES[0], "work of the joint torques since the start", "J", flows=True),
    SampleColumn(FLOW_ENTRIES[1], "energy dissipated by joint damping since the start, >= 0",
                 "J", flows=True),
)


def sample_columns(n: int, flows: bool = False) -> tuple[tuple[str, str], ...]:
    """(name, meaning) of the entries of one sample row of simulate (SAMPLE_COLUMNS) for a
    chain of n joints, with the energy-flow columns when `flows`."""
    return tuple((name, column.described(i))
                 for column in SAMPLE_COLUMNS if flows or not column.flows
                 for i, name in enumerate(column.names(n), start=1))


def sample_column_names(n: int, flows: bool = False) -> tuple[str, ...]:
    """The names of the entries of one sample row (the trajectory file's header)."""
    return tuple(name for name, _ in sample_columns(n, flows))


# --- Entry points --------------------------------------------------------------------------

@dataclass(frozen=True)
class Parameter:
    """One parameter of a C function. c_type may name the package's types through {prefix}."""

    name: str
    c_type: str


@dataclass(frozen=True)
class EntryPoint:
    """An exported function, <prefix>_<name>: its result type and parameters, the same in every
    package. `when`: the feature it needs; a package without it returns UNAVAILABLE."""

    name: str
    returns: str
    parameters: tuple[Parameter, ...]
    when: str | None = None


def _parameters(text: str) -> tuple[Parameter, ...]:
    """Parameters from 'type name, type name, ...' (the tables below stay readable)."""
    pairs = (re.fullmatch(r"(.*?[\s*])(\w+)", item.strip()).groups() for item in text.split(","))
    return tuple(Parameter(name, c_type.strip()) for c_type, name in pairs)


_WORKSPACE = "{prefix}_workspace *workspace"
#: The inputs and the run-time parameters, with their sizes: arguments of every package (NULL and
#: 0 when the scene has none), so that the signatures do not depend on the scene's features.
U_ARGUMENTS = "const double *u, int nu"
P_ARGUMENTS = "const double *p, int np"
_OPTIONS = "const {prefix}_options *options"

#: The entry points every package exports, with the same signatures whatever its features; one
#: that needs a feature the package lacks (`when`) returns UNAVAILABLE.
ENTRY_POINTS = (
    EntryPoint("workspace_size", "size_t", ()),
    EntryPoint("workspace_init", "void", _parameters(_WORKSPACE)),
    EntryPoint("default_options", "void", _parameters("{prefix}_options *options")),
    EntryPoint("dimension", "long", _parameters("int which")),
    EntryPoint("initial_state", "int", _parameters(
        f"const double *phi, const double *phidot, {P_ARGUMENTS}, double *x, {_WORKSPACE}")),
    EntryPoint("outputs", "int", _parameters(
        f"const double *x, {P_ARGUMENTS}, double *phi, double *omega, double *energy, "
        f"double *constraint_error, {_WORKSPACE}")),
    EntryPoint("holding_torques", "int", _parameters(
        f"const double *phi, {P_ARGUMENTS}, double *tau, {_WORKSPACE}"), when="inputs"),
    EntryPoint("residual", "int", _parameters(
        f"const double *z, const double *x0, {U_ARGUMENTS}, {P_ARGUMENTS}, double dt, "
        f"double *residual, {_WORKSPACE}")),
    EntryPoint("residual_jacobian", "int", _parameters(
        f"const double *z, const double *x0, {U_ARGUMENTS}, {P_ARGUMENTS}, double dt, "
        f"double *residual, double *jacobian, {_WORKSPACE}")),
    EntryPoint("step", "int", _parameters(
        f"const double *x0, {U_ARGUMENTS}, {P_ARGUMENTS}, double dt, double *x1, "
        f"double *flows, {_OPTIONS}, {_WORKSPACE}, int *iterations")),
    EntryPoint("step_sensitivities", "int", _parameters(
        f"const double *x0, {U_ARGUMENTS}, {P_ARGUMENTS}, double dt, double *x1, "
        f"double *ds_ds, double *ds_du, double *ds_dp, {_OPTIONS}, {_WORKSPACE}, "
        "int *iterations"), when="sensitivities"),
    EntryPoint("control_torques", "int", _parameters(
        f"const double *x0, {U_ARGUMENTS}, {P_ARGUMENTS}, double dt, double *tau, double *x1, "
        f"{_OPTIONS}, {_WORKSPACE}, int *iterations"), when="control"),
    EntryPoint("sample_count", "long", _parameters("long n_steps, long every")),
    EntryPoint("simulate", "int", _parameters(
        "const double *x0, double t0, double dt, long n_steps, long every, "
        f"{U_ARGUMENTS}, {P_ARGUMENTS}, {_OPTIONS}, {_WORKSPACE}, double *samples, "
        "double *x_final, {prefix}_stats *stats")),
    EntryPoint("simulate_observed", "int", _parameters(
        "const double *x0, double t0, double dt, long n_steps, long every, "
        f"{U_ARGUMENTS}, {P_ARGUMENTS}, {_OPTIONS}, {_WORKSPACE}, double *samples, "
        "double *x_final, {prefix}_stats *stats, {prefix}_observer observer, void *context, "
        "long interval, {prefix}_control *control")),
    EntryPoint("simulate_controlled", "int", _parameters(
        "const double *x0, double t0, double dt, long n_steps, long every, "
        "{prefix}_controller controller, void *context, long hold, "
        f"{P_ARGUMENTS}, {_OPTIONS}, {_WORKSPACE}, double *samples, double *torques, "
        "double *x_final, {prefix}_stats *stats, {prefix}_control *control"), when="inputs"),
    EntryPoint("build_hash", "const char *", ()),
)
ENTRY_POINTS_BY_NAME = {entry.name: entry for entry in ENTRY_POINTS}

#: The observer type of simulate_observed: called with the steps completed so far and the
#: caller's context; a nonzero return stops the run.
OBSERVER_RETURNS = "int"
OBSERVER_PARAMETERS = _parameters("long steps, void *context")

#: The controller type of simulate_controlled: called before step k (k = 0, hold, 2 hold, ...)
#: with the time and the joint-space state at its start and the caller's context; writes the NU
#: torques held over the next `hold` steps into u. A nonzero return stops the run.
CONTROLLER_RETURNS = "int"
CONTROLLER_PARAMETERS = _parameters(
    "long step, double t, const double *phi, const double *omega, double *u, void *context")


def resolved(c_type: str, prefix: str) -> str:
    """A parameter's C type with the package's prefix filled in."""
    return c_type.format(prefix=prefix)


def manifest_entry_points(prefix: str, features: Features) -> dict[str, dict]:
    """The entry points of a package, as its manifest records them: {name: {"returns": C type,
    "parameters": [[name, C type], ...], "available": whether the package has it}}."""
    return {entry.name: {"returns": entry.returns,
                         "parameters": [[p.name, resolved(p.c_type, prefix)]
                                        for p in entry.parameters],
                         "available": features.has(entry.when)}
            for entry in ENTRY_POINTS}


#: Sizes a caller queries with <prefix>_dimension(which): (name, value of which, meaning).
DIMENSIONS = (
    ("N_JOINTS", 0, "links and revolute joints"),
    ("NX", 1, "entries of a state x"),
    ("NZ", 2, "Newton unknowns z of one step"),
    ("NU", 3, "inputs u: torques of the actuated joints (0: none)"),
    ("NP", 4, "run-time parameters p (0: none)"),
    ("NSAMPLE", 5, "entries of one sample row of simulate"),
    ("NCONSTRAINT", 6, "structural constraints of a state"),
    ("ORDER", 7, "order of the step: 2, 4 or 6"),
    ("NSTAGE", 8, "stages of a composed step (0: the scheme's step alone)"),
    ("SENSITIVITIES", 9, "1 when the package has step_sensitivities"),
)


#: The compiler flags every build of generated C uses (chaingen's own, a package's Makefile and
#: the tests): the code must stay clean under all of them.
STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")

#: The package's manifest: sizes, layouts, entry points and build flags, read by the loader.
MANIFEST = "chaingen.json"
