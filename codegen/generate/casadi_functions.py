"""From a DiscreteScheme (SymPy) to CasADi Functions and their C code.

Each generated function is one record (GeneratedFunction: name, arguments, results) made by
one builder from the scheme's expressions, translated by chaingen.generate.translation over
the arguments (SchemeTranslation) after their free symbols were checked. The Newton Jacobian
dF/dz comes from CasADi's algorithmic differentiation of the translated residual. This stage
only translates: everything it needs is on the DiscreteScheme.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import sympy as sp

from ..spatial.values import SpatialScene
from ..symbolic.schemes import DiscreteScheme
from .jacobians import (
    JACOBIAN_CHUNK,
    jacobian_by_directions,
    swept_jacobians,
    unrolled_jacobian,
)
from .node_jacobian import jacobian_by_nodes
from .sensitivities import sensitivity_functions, state_chain_functions
from .translation import GeneratedFunction as GeneratedFunction
from .translation import MissingInputError as MissingInputError
from .translation import SympyToCasadi as SympyToCasadi
from .translation import check_free_symbols as check_free_symbols
from .translation import sx_vector


@dataclass(frozen=True)
class SchemeFunctions:
    """The CasADi Functions of one scheme, named with the package prefix.

    Step functions take (z, x0, u, dt), u the torques of the actuated joints; an unactuated
    scene's functions take (z, x0, dt): no input path at all.
    """

    residual: ca.Function            # -> F
    residual_jacobian: ca.Function   # -> (F, dF/dz dense, column-major)
    predictor: ca.Function           # (x0, dt) -> z
    next_state: ca.Function          # -> x1, and flows = (input work, dissipated) if any
    outputs: ca.Function             # (x) -> (phi, omega, energy, constraint residuals)
    initial_state: ca.Function       # (phi, phidot) -> x
    # Step-map sensitivities in joint space s = (phi, omega), by the implicit function theorem:
    # (None when the package is generated without them.)
    sensitivity_rhs: ca.Function | None  # -> R = [dF/dx0 dx0/ds0, dF/du]  (nz x (2n + nu))
    sensitivity_map: ca.Function | None  # -> (ds1/dz, ds1/dx0 dx0/ds0, ds1/du) at fixed z
    # A composed step whose state x the joint-space state does not determine (es) chains its
    # stages in x instead: then sensitivity_rhs -> [dF/dx0, dF/du, dF/dp], sensitivity_map ->
    # (dx1/dz, dx1/dx0, dx1/du, dx1/dp), and joint_maps (x0, x1) -> (dx0/ds0, dx0/dp at
    # s0 = S(x0), ds1/dx1, ds1/dp at x1) maps the chained Jacobians to joint space.
    joint_maps: ca.Function | None
    holding_torques: ca.Function | None  # (phi) -> dV/dphi, actuated scenes only
    segment_margins: ca.Function | None  # (x0, x1) -> (s_j(x1) / tol_j, cos of each segment's
                                         # turn over the step), scenes with springs only
    energy_check: ca.Function | None = None  # (x) -> (H, T, S), schemes with a kinetic_energy
    parameters: ca.Function | None = None  # p -> q, the derived parameters the others take
    # es's Newton matrix by its factors (DiscreteScheme.arm_space): -> (F, factors), factors =
    # (H's nonzeros, G_mu, G_c, m, A) as runtime/c/chaingen_arm_solve.h reads them; and H's
    # pattern, (rows, columns) of its nonzeros in that order. None: dense LU of dF/dz.
    newton_factors: ca.Function | None = None
    arm_pattern: tuple[tuple[int, ...], tuple[int, ...]] | None = None
    # -> (F, factors) with H taken of ArmSpace.newton_forces (the springs' quadrature without
    # the exact gradient's correction), in newton_factors' layout and pattern: the chord's
    # Newton matrix (model.md 18); None: newton_factors serves the chord too.
    chord_factors: ca.Function | None = None
    # -> y, the step's constants those take as their last input (generate.step_constants)
    step_constants: ca.Function | None = None
    # -> (F, A): the scheme's Newton matrix A ~ dF/dz (StepSystem.newton_matrix), which Newton
    # takes in place of dF/dz; None: dF/dz.
    newton_matrix: ca.Function | None = None
    # -> tau[nu]: the torques the actuated joints apply over the step (EnergyFlows'
    # applied_torques, a control law solved in the step); None without one.
    applied_torques: ca.Function | None = None

    def all(self) -> tuple[ca.Function, ...]:
        """The functions of the generated C. A package with newton_factors forms its
        residual_jacobian from them (chaingen_arm_solve.h): CasADi's stays in Python."""
        dense = self.residual_jacobian if self.newton_factors is None else None
        functions = (self.residual, dense, self.predictor, self.next_state,
                     self.outputs, self.initial_state, self.sensitivity_rhs,
                     self.sensitivity_map, self.joint_maps, self.holding_torques,
                     self.segment_margins, self.energy_check, self.newton_factors,
                     self.chord_factors, self.parameters, self.newton_matrix,
                     self.applied_torques, self.step_constants)
        return tuple(function for function in functions if function is not None)

    def derivatives(self) -> tuple[ca.Function, ...]:
        """The functions a forward run's step never calls, in their own C file (package.py):
        the step sensitivities' and, where the chord has its own factors, dF/dz's (for
        residual_jacobian, the sensitivities and full Newton)."""
        exact = self.newton_factors if self.chord_factors is not None else None
        functions = (self.sensitivity_rhs, self.sensitivity_map, self.joint_maps, exact)
        return tuple(function for function in functions if function is not None)


def chains_state(scheme: DiscreteScheme) -> bool:
    """Whether a composed step's sensitivities chain its stages in the whole state x (es,
    whose x carries a normal velocity the joint-space state does not see) rather than in
    joint space (SchemeFunctions.joint_maps)."""
    return len(scheme.metadata.composition) > 1 and not scheme.maps.state_from_joint_space


class SchemeTranslation:
    """The CasADi arguments of a scheme's functions, and its SymPy expressions translated over
    them: step functions take (z, x0, u, p, dt), the state's (x, p), the initial state's (phi,
    phidot, p). u is left out where the scene has no inputs, p where it has no parameters.

    Every expression is checked before it is translated: each free symbol must be an input of
    the function it goes into or a definition (StepSystem.definitions and the state's and the
    initial state's) made of those, or MissingInputError names the missing ones."""

    def __init__(self, scheme: DiscreteScheme):
        self.scheme = scheme
        maps, step = scheme.maps, scheme.step
        self.nz, self.nx = step.unknowns.shape[0], maps.state.shape[0]
        self.nu = scheme.flows.inputs.shape[0]
        self.n, self.n_p = scheme.scene.n, scheme.run_parameters.symbols.shape[0]
        if segment_dimension(scheme) * len(scheme.segments.tolerances) != \
                scheme.segments.vectors.shape[0]:
            raise ValueError(f"{scheme.metadata.method}: one segment tolerance per spring "
                             "segment")
        self.parameters = list(scheme.run_parameters.symbols)
        # The symbols each kind of function may use: its inputs, then its definitions in order.
        self.step_symbols = defined("definition", scheme.step_inputs, step.definitions)
        self.state_symbols = defined("state definition", list(maps.state) + self.parameters,
                                     maps.state_definitions)
        self.initial_symbols = defined(
            "initial definition",
            list(maps.initial_angles) + list(maps.initial_velocities) + self.parameters,
            maps.initial_definitions)

        self.z, self.x0 = ca.SX.sym("z", self.nz), ca.SX.sym("x0", self.nx)
        self.u, self.p, self.dt = ca.SX.sym("u", self.nu), ca.SX.sym("p", self.n_p), ca.SX.sym("dt")
        self.x = ca.SX.sym("x", self.nx)
        self.phi, self.phidot = ca.SX.sym("phi", self.n), ca.SX.sym("phidot", self.n)
        self.parameter_bindings = dict(zip(self.parameters, ca.vertsplit(self.p)))
        self.bindings = dict(zip(step.unknowns, ca.vertsplit(self.z)))
        self.bindings.update(zip(maps.state, ca.vertsplit(self.x0)))
        self.bindings.update(zip(scheme.flows.inputs, ca.vertsplit(self.u)))
        self.bindings.update(self.parameter_bindings)
        self.bindings[step.dt] = self.dt
        self.step = bind_all(SympyToCasadi(self.bindings, self.parameters), step.definitions)
        self.with_p = ([self.p] if self.n_p else [], ["p"] if self.n_p else [])
        self.step_args = ([self.z, self.x0] + ([self.u] if self.nu else []) + self.with_p[0]
                          + [self.dt])
        self.step_names = (["z", "x0"] + (["u"] if self.nu else []) + self.with_p[1] + ["dt"])
        self.residual = self.translated("residual", step.residual, self.step, self.step_symbols)
        self.jacobian = unrolled_jacobian(self.residual, self.z,
                                          [self.z, self.x0, self.u, self.p, self.dt])
        self.next_state = self.translated("next_state", step.next_state, self.step,
                                          self.step_symbols)
        initial = bind_all(SympyToCasadi({**dict(zip(maps.initial_angles,
                                                     ca.vertsplit(self.phi))),
                                          **dict(zip(maps.initial_velocities,
                                                     ca.vertsplit(self.phidot))),
                                          **self.parameter_bindings}, self.parameters),
                           maps.initial_definitions)
        self.initial_state = self.translated("initial_state", maps.initial_state, initial,
                                             self.initial_symbols)
        flows = scheme.flows
        self.flows = ([self.translated("energy flows", [flows.input_work, flows.dissipated],
                                       self.step, self.step_symbols)]
                      if scheme.has_energy_flows else [])

    @staticmethod
    def translated(name: str, expressions, translate: SympyToCasadi, symbols) -> ca.SX:
        """`expressions` as a CasADi column, once every free symbol of theirs is one of
        `symbols` (else MissingInputError, naming `name` and the missing ones)."""
        check_free_symbols(name, expressions, symbols)
        return sx_vector(translate, expressions)

    def state_translator(self, state: ca.SX, extra: dict | None = None) -> SympyToCasadi:
        """Expressions in the state, p and the state definitions, bound to `state`."""
        bindings = dict(zip(self.scheme.maps.state, ca.vertsplit(state)))
        bindings.update(self.parameter_bindings)
        bindings.update(extra or {})
        return bind_all(SympyToCasadi(bindings, self.parameters),
                        self.scheme.maps.state_definitions)

    def joint_space(self, state: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """(phi, omega, energy, constraint residuals) of a state, as expressions in it."""
        maps, translate = self.scheme.maps, self.state_translator(state)
        symbols = self.state_symbols
        return (self.translated("outputs", maps.joint_angles, translate, symbols),
                self.translated("outputs", maps.joint_velocities, translate, symbols),
                self.translated("outputs", [maps.energy], translate, symbols),
                self.translated("outputs", maps.constraint_residuals, translate, symbols))

    def state_tangent(self, state: ca.SX, s_seed: ca.SX, p_seed: ca.SX) -> ca.SX:
        """dx0 = X_s ds0 + X_p dp of x0 = X(s0, p) (initial_state) at s0 = S(state, p), in
        the directions of the columns of s_seed (2n rows) and p_seed (np rows)."""
        s_of_state = ca.vertcat(*self.joint_space(state)[:2])
        seed = ca.SX.sym("seed", 2 * self.n + self.n_p, s_seed.shape[1])
        tangent = ca.Function("X", [self.phi, self.phidot, self.p, seed],
                              [ca.jtimes(self.initial_state,
                                         ca.vertcat(self.phi, self.phidot, self.p), seed)])
        return tangent(s_of_state[:self.n], s_of_state[self.n:], self.p,
                       ca.vertcat(s_seed, p_seed))

    def state_maps(self) -> tuple[ca.SX, ca.SX]:
        """X_s = dx0/ds0 and X_p = dx0/dp of x0 = X(s0, p) (initial_state) at s0 = S(x0, p)."""
        s_of_x0 = ca.vertcat(*self.joint_space(self.x0)[:2])
        maps = ca.Function("X", [self.phi, self.phidot, self.p],
                           [ca.jacobian(self.initial_state, ca.vertcat(self.phi, self.phidot)),
                            ca.jacobian(self.initial_state, self.p)])
        return maps(s_of_x0[:self.n], s_of_x0[self.n:], self.p)

    def step_function(self, name: str, outputs, output_names) -> GeneratedFunction:
        """A function of the step's arguments (z, x0, u, p, dt)."""
        return GeneratedFunction(name, tuple(self.step_args), tuple(self.step_names),
                                 tuple(outputs), tuple(output_names))


def defined(kind: str, inputs, definitions) -> list:
    """`inputs` followed by the symbols of `definitions`, each checked to be made of the
    inputs and the definitions before it."""
    symbols = list(inputs)
    for symbol, expression in definitions:
        check_free_symbols(f"{kind} of {symbol}", [expression], symbols)
        symbols.append(symbol)
    return symbols


def segment_dimension(scheme: DiscreteScheme) -> int:
    """The entries of each spring segment's vector: (dx, dy) for a planar chain, (dx, dy, dz)
    for a spatial one."""
    return 3 if isinstance(scheme.scene, SpatialScene) else 2


def bind_all(translate: SympyToCasadi, definitions) -> SympyToCasadi:
    """`translate` with the symbols of `definitions` bound, in order."""
    for symbol, expression in definitions:
        translate.bind(symbol, translate(expression), translate.is_parametric(expression))
    return translate


# -- one builder per generated function ----------------------------------------------------

def segment_margins(t: SchemeTranslation) -> GeneratedFunction | None:
    """(x0, x1) -> (s_j(x1) / tol_j, cos of each segment's turn over the step), at the scene's
    own numbers (its tolerances are the scene's); None for a scene without springs."""
    vectors = t.scheme.segments.vectors
    if not vectors.shape[0]:
        return None
    tolerances = ca.DM(list(t.scheme.segments.tolerances))
    rows = segment_dimension(t.scheme)
    before = ca.reshape(t.translated("segment_vectors", vectors, t.state_translator(t.x0),
                                     t.state_symbols), rows, -1)
    after = ca.reshape(t.translated("segment_vectors", vectors, t.state_translator(t.x),
                                    t.state_symbols), rows, -1)
    lengths_before = ca.sqrt(ca.sum1(before ** 2)).T
    lengths_after = ca.sqrt(ca.sum1(after ** 2)).T
    turn = ca.sum1(before * after).T / (lengths_before * lengths_after)
    return GeneratedFunction("segment_margins", tuple([t.x0, t.x] + t.with_p[0]),
                             tuple(["x0", "x1"] + t.with_p[1]),
                             (ca.vertcat(lengths_after / tolerances, turn),), ("margins",))


def energy_check(t: SchemeTranslation) -> GeneratedFunction | None:
    """(x) -> (H, T, S), schemes with a kinetic_energy (model.md 13). S, the sum of |H's terms|,
    scales H's round-off: a controlled loop's H_d cancels joules to nothing at its target."""
    maps = t.scheme.maps
    if maps.kinetic_energy is None:
        return None
    translate, symbols = t.state_translator(t.x), t.state_symbols
    terms = t.translated("outputs", list(sp.Add.make_args(maps.energy)), translate, symbols)
    energies = ca.vertcat(t.translated("outputs", [maps.energy, maps.kinetic_energy], translate,
                                       symbols), ca.sum1(ca.fabs(terms)))
    return GeneratedFunction("energy_check", tuple([t.x] + t.with_p[0]),
                             tuple(["x"] + t.with_p[1]), (energies,), ("H_T_S",))


def holding_torques(t: SchemeTranslation) -> GeneratedFunction | None:
    """(phi) -> dV/dphi, for an actuated scene."""
    maps = t.scheme.maps
    if maps.holding_torques is None:
        return None
    # They may use the initial state's definitions (a spatial chain's recursion), all bound;
    # the function takes the angles alone, so no symbol of the velocities may reach them.
    translate = bind_all(SympyToCasadi({**dict(zip(maps.initial_angles, ca.vertsplit(t.phi))),
                                        **dict(zip(maps.initial_velocities,
                                                   ca.vertsplit(t.phidot))),
                                        **t.parameter_bindings}, t.parameters),
                         maps.initial_definitions)
    velocities = set(maps.initial_velocities)
    torques = t.translated("holding_torques", maps.holding_torques, translate,
                           [symbol for symbol in t.initial_symbols if symbol not in velocities])
    return GeneratedFunction("holding_torques", tuple([t.phi] + t.with_p[0]),
                             tuple(["phi"] + t.with_p[1]), (torques,), ("tau",))


def newton_factors(t: SchemeTranslation) -> tuple[GeneratedFunction | None,
                                                 GeneratedFunction | None, tuple | None]:
    """es's Newton matrix by its factors (ArmSpace): -> (F, factors); the chord's, of
    ArmSpace.newton_forces, where it has them (else None); and H's pattern, which both share."""
    arms = t.scheme.step.arm_space
    if arms is None:
        return None, None, None
    exact, chord, pattern = arm_factors(t.scheme, t.bindings, t.parameters, t.step, t.z)
    return (t.step_function("newton_factors", [t.residual, exact], ["F", "factors"]),
            None if chord is None else
            t.step_function("chord_factors", [t.residual, chord], ["F", "factors"]), pattern)


def newton_matrix(t: SchemeTranslation) -> GeneratedFunction | None:
    """-> (F, A), the scheme's Newton matrix A ~ dF/dz (StepSystem.newton_matrix), dense,
    column-major; None for a scheme without one."""
    matrix = t.scheme.step.newton_matrix
    if matrix is None:
        return None
    entries = t.translated("newton_matrix", list(matrix), t.step, t.step_symbols)
    # list(matrix) is row by row; the runtime reads A column by column
    return t.step_function("newton_matrix", [t.residual, ca.reshape(entries, t.nz, t.nz).T],
                           ["F", "A"])


def applied_torques(t: SchemeTranslation) -> GeneratedFunction | None:
    """-> tau[nu], the torque each actuated joint applies over the step (EnergyFlows'
    applied_torques) at the step's arguments; None for a scheme without a control law."""
    torques = t.scheme.flows.applied_torques
    if torques is None:
        return None
    if torques.shape != (t.nu, 1) or not t.nu:
        raise ValueError(f"{t.scheme.metadata.method}: applied_torques must be a column of one "
                         f"torque per actuated joint ({t.nu}), not {torques.shape[0]} x "
                         f"{torques.shape[1]}")
    return t.step_function("applied_torques",
                           [t.translated("applied_torques", torques, t.step, t.step_symbols)],
                           ["tau"])


def predictor(t: SchemeTranslation) -> GeneratedFunction:
    """(x0, p, dt) -> z: the first Newton guess; it may use the state definitions (vi:
    w = M^-1 p by its recursion)."""
    step = t.scheme.step
    if not any(step.predictor):
        guess = ca.SX.zeros(step.unknowns.shape[0], 1)
    else:
        guess = t.translated("predictor", step.predictor,
                             t.state_translator(t.x0, {step.dt: t.dt}),
                             t.state_symbols + [step.dt])
    return GeneratedFunction("predictor", tuple([t.x0] + t.with_p[0] + [t.dt]),
                             tuple(["x0"] + t.with_p[1] + ["dt"]), (guess,), ("z",))


def scheme_functions(scheme: DiscreteScheme, prefix: str, *,
                     sensitivities: bool = True) -> SchemeFunctions:
    """CasADi Functions for the residual, its Jacobian, and the state maps of `scheme`.

    Every function that depends on the model takes the run-time parameters (when the scheme
    has any) after its state-like inputs: step functions (z, x0, u, q, dt), the predictor
    (x0, q, dt), outputs (x, q), initial_state (phi, phidot, q), holding_torques (phi, q),
    where q = parameters(p) are the derived parameters (see build_functions).
    sensitivities=False leaves out the step-map Jacobians (chaingen.generate.sensitivities),
    the largest generated functions, when a package does not need them.
    """
    t = SchemeTranslation(scheme)
    found: dict[str, GeneratedFunction | None] = dict.fromkeys(
        ("sensitivity_rhs", "sensitivity_map", "joint_maps"))
    if sensitivities and chains_state(scheme):
        found.update(zip(found, state_chain_functions(t)))
    elif sensitivities:
        found.update(zip(found, sensitivity_functions(t)))
    found["segment_margins"] = segment_margins(t)
    found["energy_check"] = energy_check(t)
    found["holding_torques"] = holding_torques(t)
    found["newton_factors"], found["chord_factors"], pattern = newton_factors(t)
    found["newton_matrix"] = newton_matrix(t)
    found["applied_torques"] = applied_torques(t)
    jacobian = t.residual if t.jacobian is None else t.jacobian
    found.update(
        residual=t.step_function("residual", [t.residual], ["F"]),
        residual_jacobian=t.step_function("residual_jacobian", [t.residual, jacobian],
                                          ["F", "J"]),
        predictor=predictor(t),
        next_state=t.step_function("next_state", [t.next_state] + t.flows,
                                   ["x1"] + (["flows"] if t.flows else [])),
        outputs=GeneratedFunction("outputs", tuple([t.x] + t.with_p[0]),
                                  tuple(["x"] + t.with_p[1]), tuple(t.joint_space(t.x)),
                                  ("phi", "omega", "energy", "constraint")),
        initial_state=GeneratedFunction("initial_state",
                                        tuple([t.phi, t.phidot] + t.with_p[0]),
                                        tuple(["phi", "phidot"] + t.with_p[1]),
                                        (t.initial_state,), ("x",)))
    directions = None if t.jacobian is not None else JACOBIAN_CHUNK
    by_nodes = (t.jacobian is None and scheme.step.node_space is not None and not t.n_p)
    if by_nodes:
        del found["residual_jacobian"]
    built = build_functions([function for function in found.values() if function is not None],
                            prefix, t.p, {"cse": True}, directions,
                            scheme.step.jacobian_blocks)
    if by_nodes:
        found["residual_jacobian"] = t.step_function("residual_jacobian", [], [])
        built["residual_jacobian"] = jacobian_by_nodes(t, f"{prefix}_model_residual_jacobian",
                                                       {"cse": True})
    return SchemeFunctions(**{field: None if function is None else built[function.name]
                              for field, function in found.items()},
                           parameters=built.get(PARAMETERS_FUNCTION), arm_pattern=pattern)


def arm_factors(scheme: DiscreteScheme, bindings: dict, parameters: list,
                 step: SympyToCasadi, z: ca.SX) -> tuple[ca.SX, ca.SX | None, tuple]:
    """The factors of es's Newton matrix (ArmSpace) as one vector in the step's inputs; those
    of the chord's Newton matrix, H taken of ArmSpace.newton_forces (None without them); and
    H's pattern, the union of both H's, in which both vectors give its nonzeros. h and c are
    translated with the arm increments w as free symbols, so that dh/dw and dc/dw are CasADi's
    sparse symbolic Jacobians (a few entries per link), then w is put back as the function of z
    it is. Raises ValueError if h or c depend on dv other than through w, or the blocks of
    G_mu and G_c are not one 2-vector per link."""
    arms = scheme.step.arm_space
    n = scheme.scene.n
    w = ca.SX.sym("w", 2 * n)
    free = dict(zip(arms.arm_increments, ca.vertsplit(w)))
    local = SympyToCasadi(dict(bindings), parameters)
    for symbol, expression in scheme.step.definitions:
        if symbol in free:
            local.bind(symbol, free[symbol])
        else:
            local.bind(symbol, local(expression), local.is_parametric(expression))
    forces = sx_vector(local, arms.forces)
    rows = sx_vector(local, scheme.step.residual[2 * n:, :])
    if ca.jacobian(ca.vertcat(forces, rows), z[:2 * n]).nnz():
        raise ValueError("es: the arm forces depend on dv other than through w = B dv")
    H = ca.jacobian(forces, w)
    chord_H = None
    if arms.newton_forces is not None:
        chord_H = ca.jacobian(sx_vector(local, arms.newton_forces), w)
        union = H.sparsity() + chord_H.sparsity()
        H, chord_H = ca.project(H, union), ca.project(chord_H, union)
    g_mu = ca.jacobian(forces, z[2 * n:])
    g_c = ca.jacobian(rows, w)
    for name, block, shape in (("G_mu", g_mu, lambda r, c: r // 2 == c),
                               ("G_c", g_c, lambda r, c: c // 2 == r)):
        if not all(shape(r, c) for r, c in zip(*block.sparsity().get_triplet())):
            raise ValueError(f"es: {name} is not one 2-vector per link")
    g_mu = ca.vertcat(*[g_mu[r, r // 2] for r in range(2 * n)])
    g_c = ca.vertcat(*[g_c[c // 2, c] for c in range(2 * n)])
    arm_increments = ca.vertcat(*[step(symbol) for symbol in arms.arm_increments])
    constants = ca.vertcat(sx_vector(step, arms.masses), sx_vector(step, arms.maps))

    def factors(jacobian):
        local_values = ca.substitute(ca.vertcat(*jacobian.nonzeros(), g_mu, g_c), w,
                                     arm_increments)
        return ca.vertcat(local_values, constants)

    rows_h, columns_h = H.sparsity().get_triplet()
    return (factors(H), None if chord_H is None else factors(chord_H),
            (tuple(rows_h), tuple(columns_h)))


#: The name of the generated function that computes the derived parameters q from p.
PARAMETERS_FUNCTION = "parameters"


def build_functions(functions: list[GeneratedFunction], prefix: str, p: ca.SX, options: dict,
                    directions: int | None = None, blocks=()) -> dict[str, ca.Function]:
    """The generated functions as CasADi Functions, by name. With run-time parameters p,
    every subexpression that depends on p alone is hoisted out of them (CasADi's
    extract_parametric, one pass over all of them, so a subexpression they share is one
    entry): a function `parameters` computes those, q = Q(p), and every other function takes
    q in p's place. The C code evaluates Q once when p changes instead of in every residual
    of every step. directions: the Newton Jacobian's forward directions per pass (None:
    unrolled); blocks: the blocks of z it differentiates separately (StepSystem's
    jacobian_blocks)."""
    sweeps = {f.name: f.sweep for f in functions if f.sweep is not None}

    def function(name, inputs, input_names, outputs, output_names):
        if name == "residual_jacobian" and directions:   # z is the first input
            return jacobian_by_directions(f"{prefix}_model_{name}", inputs, input_names,
                                          outputs[0], 0, directions, options, blocks)
        if name in sweeps:   # the seed is the last input
            directional = ca.Function(f"{prefix}_model_{name}_directions", inputs, outputs,
                                      input_names, output_names, options)
            return swept_jacobians(f"{prefix}_model_{name}", directional, sweeps[name],
                                   input_names[:-1])
        return ca.Function(f"{prefix}_model_{name}", inputs, outputs, input_names, output_names,
                           options)

    if p.shape[0] == 0:
        return {f.name: function(f.name, list(f.inputs), list(f.input_names), list(f.outputs),
                                 list(f.output_names)) for f in functions}
    expressions = [output for f in functions for output in f.outputs]
    hoisted, symbols, values = ca.extract_parametric(expressions, p,
                                                     {"extract_trivial": True, "prefix": "q_"})
    q = ca.vertcat(*symbols) if symbols else ca.SX(0, 1)
    built = {PARAMETERS_FUNCTION: function(PARAMETERS_FUNCTION, [p], ["p"],
                                           [ca.vertcat(*values) if values else ca.SX(0, 1)],
                                           ["q"])}
    start = 0
    for f in functions:
        rewritten = list(hoisted[start:start + len(f.outputs)])
        start += len(f.outputs)
        inputs = [q if item is p else item for item in f.inputs]
        input_names = ["q" if item == "p" else item for item in f.input_names]
        built[f.name] = function(f.name, inputs, input_names, rewritten, list(f.output_names))
    return built
