"""From a DiscreteScheme (SymPy) to CasADi Functions and their C code.

SymPy expressions are translated node by node into CasADi SX, memoised on the expression so
that a subexpression SymPy shares is built once; CasADi's CSE then shares the rest. The Newton
Jacobian dF/dz comes from CasADi's algorithmic differentiation of the translated residual. This
stage only translates: everything it needs is on the DiscreteScheme.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import sympy as sp

from ..symbolic.schemes import DiscreteScheme
from .jacobians import JACOBIAN_CHUNK, jacobian_by_directions, unrolled_jacobian

#: SymPy functions with a CasADi counterpart of the same meaning.
_FUNCTIONS = {
    sp.sin: ca.sin, sp.cos: ca.cos, sp.tan: ca.tan, sp.exp: ca.exp, sp.log: ca.log,
    sp.atan: ca.atan, sp.Abs: ca.fabs, sp.atan2: ca.atan2,
}


class MissingInputError(ValueError):
    """An expression has a free symbol that is not an input of the function being built."""


def check_free_symbols(name: str, expressions, inputs) -> None:
    """Every free symbol of `expressions` must be one of `inputs` (style.md), or raise."""
    declared = set(inputs)
    missing = set()
    for expr in expressions:
        missing |= set(expr.free_symbols) - declared
    if missing:
        names = ", ".join(sorted(map(str, missing)))
        raise MissingInputError(f"{name}: free symbols {names} are not inputs of the function")


class SympyToCasadi:
    """Translate SymPy expressions into CasADi SX over given symbol -> SX bindings.

    `parametric`: symbols of run-time parameters. A sum or product then combines its terms that
    depend on parameters alone first, so that they form subexpressions of their own (m1 * m2 *
    x as (m1 * m2) * x): those are what `extract_parametric` hoists out of the step.
    """

    def __init__(self, bindings: dict[sp.Symbol, ca.SX], parametric=()):
        self._memo: dict[sp.Basic, ca.SX] = dict(bindings)
        self._parametric: set[sp.Basic] = set(parametric)
        self._grouping = bool(self._parametric)

    def bind(self, symbol: sp.Symbol, value: ca.SX, parametric: bool = False) -> None:
        """Bind one more symbol (an intermediate defined by earlier bindings)."""
        self._memo[symbol] = value
        if parametric:
            self._parametric.add(symbol)

    def is_parametric(self, expr: sp.Basic) -> bool:
        """Whether a translated expression depends on the parameters (and numbers) alone."""
        return expr in self._parametric or expr.is_Number

    def __call__(self, expr: sp.Basic) -> ca.SX:
        # Iterative post-order walk: deep recursive expressions (long chains) must not hit
        # Python's recursion limit.
        memo = self._memo
        stack = [(expr, False)]
        while stack:
            node, expanded = stack.pop()
            if node in memo:
                continue
            if node.is_Number:
                memo[node] = ca.SX(float(node))
                continue
            if node.is_Symbol:
                raise MissingInputError(f"symbol {node} has no binding")
            if not expanded:
                stack.append((node, True))
                stack.extend((arg, False) for arg in node.args if arg not in memo)
                continue
            args = node.args
            if self._grouping:
                flags = [self.is_parametric(arg) for arg in args]
                if all(flags):
                    self._parametric.add(node)
                elif (node.is_Add or node.is_Mul) and any(flags):
                    # parameter-only terms first: they combine into one hoistable subtotal
                    args = tuple(arg for arg, flag in zip(args, flags) if flag) + tuple(
                        arg for arg, flag in zip(args, flags) if not flag)
            memo[node] = self._combine(node, [memo[arg] for arg in args])
        return memo[expr]

    @staticmethod
    def _combine(node: sp.Basic, args: list[ca.SX]) -> ca.SX:
        if node.is_Add:
            total = args[0]
            for term in args[1:]:
                total = total + term
            return total
        if node.is_Mul:
            product = args[0]
            for factor in args[1:]:
                product = product * factor
            return product
        if node.is_Pow:
            base, exponent = args
            e = node.exp
            if e == sp.Rational(1, 2):
                return ca.sqrt(base)
            if e == -sp.Rational(1, 2):
                return 1 / ca.sqrt(base)
            if e == -1:
                return 1 / base
            if e.is_Integer and e > 0:
                return ca.constpow(base, exponent)
            return ca.power(base, exponent)
        for sympy_function, casadi_function in _FUNCTIONS.items():
            if isinstance(node, sympy_function):
                return casadi_function(*args)
        raise NotImplementedError(f"no CasADi translation for {type(node).__name__}: {node}")


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
    energy_check: ca.Function | None = None  # (x) -> (H, T): schemes with a kinetic_energy
                                             # only
    parameters: ca.Function | None = None  # p -> q, the derived parameters every other
                                           # function takes in p's place (packages with p)
    # es's Newton matrix by its factors (DiscreteScheme.arm_space): -> (F, factors), factors =
    # (H's nonzeros, G_mu, G_c, m, A) as runtime/c/chaingen_arm_solve.h reads them; and H's
    # pattern, (rows, columns) of its nonzeros in that order. None: dense LU of dF/dz.
    newton_factors: ca.Function | None = None
    arm_pattern: tuple[tuple[int, ...], tuple[int, ...]] | None = None

    def all(self) -> tuple[ca.Function, ...]:
        """The functions of the generated C. A package with newton_factors forms its
        residual_jacobian from them (chaingen_arm_solve.h): CasADi's stays in Python."""
        dense = self.residual_jacobian if self.newton_factors is None else None
        functions = (self.residual, dense, self.predictor, self.next_state,
                     self.outputs, self.initial_state, self.sensitivity_rhs,
                     self.sensitivity_map, self.joint_maps, self.holding_torques,
                     self.segment_margins, self.energy_check, self.newton_factors,
                     self.parameters)
        return tuple(function for function in functions if function is not None)


def _vector(translate: SympyToCasadi, matrix) -> ca.SX:
    entries = [translate(e) for e in matrix]
    return ca.vertcat(*entries) if entries else ca.SX(0, 1)


def chains_state(scheme: DiscreteScheme) -> bool:
    """Whether a composed step's sensitivities chain its stages in the whole state x (es,
    whose x carries a normal velocity the joint-space state does not see) rather than in
    joint space (SchemeFunctions.joint_maps)."""
    return len(scheme.metadata.composition) > 1 and not scheme.maps.state_from_joint_space


def scheme_functions(scheme: DiscreteScheme, prefix: str, *,
                     sensitivities: bool = True) -> SchemeFunctions:
    """CasADi Functions for the residual, its Jacobian, and the state maps of `scheme`.

    Every function that depends on the model takes the run-time parameters (when the scheme
    has any) after its state-like inputs: step functions (z, x0, u, q, dt), the predictor
    (x0, q, dt), outputs (x, q), initial_state (phi, phidot, q), holding_torques (phi, q),
    where q = parameters(p) are the derived parameters (see _build).
    sensitivities=False leaves out the step-map Jacobians, the largest generated functions
    (for "vi" about three times the Newton Jacobian), when a package does not need them.
    """
    maps = scheme.maps
    nz, nx, nu = (scheme.step.unknowns.shape[0], maps.state.shape[0],
                  scheme.flows.inputs.shape[0])
    n, n_p = scheme.scene.n, scheme.run_parameters.symbols.shape[0]
    if 2 * len(scheme.segments.tolerances) != scheme.segments.vectors.shape[0]:
        raise ValueError(f"{scheme.metadata.method}: one segment tolerance per spring segment")
    z, x0, u = ca.SX.sym("z", nz), ca.SX.sym("x0", nx), ca.SX.sym("u", nu)
    p, dt = ca.SX.sym("p", n_p), ca.SX.sym("dt")
    parameters = list(scheme.run_parameters.symbols)
    step_inputs = scheme.step_inputs
    for symbol, expression in scheme.step.definitions:
        check_free_symbols(f"definition of {symbol}", [expression], step_inputs)
        step_inputs.append(symbol)
    for name, exprs in (("residual", scheme.step.residual), ("next_state", scheme.step.next_state),
                        ("energy flows", [scheme.flows.input_work, scheme.flows.dissipated])):
        check_free_symbols(name, exprs, step_inputs)
    solve = scheme.maps.output_solve
    solved = list(solve.symbols) if solve else []
    state_inputs = list(scheme.maps.state) + parameters
    for symbol, expression in scheme.maps.state_definitions:
        check_free_symbols(f"state definition of {symbol}", [expression], state_inputs)
        state_inputs.append(symbol)
    initial_inputs = list(maps.initial_angles) + list(maps.initial_velocities) + parameters
    for symbol, expression in scheme.maps.initial_definitions:
        check_free_symbols(f"initial definition of {symbol}", [expression], initial_inputs)
        initial_inputs.append(symbol)
    check_free_symbols("predictor", scheme.step.predictor, state_inputs + solved + [scheme.step.dt])
    if solve:
        check_free_symbols("output_solve", list(solve.matrix) + list(solve.rhs), state_inputs)
    check_free_symbols("outputs", list(maps.joint_angles) + list(maps.joint_velocities)
                       + [scheme.maps.energy] + list(scheme.maps.constraint_residuals)
                       + [e for e in [scheme.maps.kinetic_energy] if e is not None],
                       state_inputs + solved)
    check_free_symbols("segment_vectors", scheme.segments.vectors, state_inputs)
    if scheme.maps.holding_torques is not None:
        check_free_symbols("holding_torques", scheme.maps.holding_torques,
                           list(scheme.maps.initial_angles) + parameters)
    check_free_symbols("initial_state", scheme.maps.initial_state, initial_inputs)

    parameter_bindings = dict(zip(parameters, ca.vertsplit(p)))
    bindings = dict(zip(scheme.step.unknowns, ca.vertsplit(z)))
    bindings.update(zip(scheme.maps.state, ca.vertsplit(x0)))
    bindings.update(zip(scheme.flows.inputs, ca.vertsplit(u)))
    bindings.update(parameter_bindings)
    bindings[scheme.step.dt] = dt
    step = SympyToCasadi(bindings, parameters)
    for symbol, expression in scheme.step.definitions:
        step.bind(symbol, step(expression), step.is_parametric(expression))
    residual = _vector(step, scheme.step.residual)
    jacobian = unrolled_jacobian(residual, z, [z, x0, u, p, dt])
    directions = None if jacobian is not None else JACOBIAN_CHUNK
    x1 = _vector(step, scheme.step.next_state)
    options = {"cse": True}

    def bind_all(translate: SympyToCasadi, definitions) -> SympyToCasadi:
        for symbol, expression in definitions:
            translate.bind(symbol, translate(expression), translate.is_parametric(expression))
        return translate

    def state_translator(state: ca.SX, extra: dict | None = None) -> SympyToCasadi:
        """Expressions in the state, p, the state definitions and the output_solve symbols,
        bound to `state`."""
        state_bindings = dict(zip(scheme.maps.state, ca.vertsplit(state)))
        state_bindings.update(parameter_bindings)
        state_bindings.update(extra or {})
        bound = bind_all(SympyToCasadi(state_bindings, parameters), scheme.maps.state_definitions)
        if solve:
            matrix = ca.vertcat(*[ca.horzcat(*[bound(e) for e in row])
                                  for row in solve.matrix.tolist()])
            solution = ca.solve(matrix, _vector(bound, solve.rhs))
            for symbol, value in zip(solve.symbols, ca.vertsplit(solution)):
                bound.bind(symbol, value)
        return bound

    def joint_space(state: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """(phi, omega, energy, constraint residuals) of a state, as expressions in it."""
        translate = state_translator(state)
        return (_vector(translate, scheme.maps.joint_angles),
                _vector(translate, scheme.maps.joint_velocities), translate(scheme.maps.energy),
                _vector(translate, scheme.maps.constraint_residuals))

    x = ca.SX.sym("x", nx)
    phi, phidot = ca.SX.sym("phi", n), ca.SX.sym("phidot", n)
    initial = bind_all(SympyToCasadi({**dict(zip(scheme.maps.initial_angles, ca.vertsplit(phi))),
                                      **dict(zip(scheme.maps.initial_velocities,
                                                 ca.vertsplit(phidot))),
                                      **parameter_bindings}, parameters),
                       scheme.maps.initial_definitions)
    initial_state = _vector(initial, scheme.maps.initial_state)

    with_p = ([p] if n_p else [], ["p"] if n_p else [])
    step_args = [z, x0] + ([u] if nu else []) + with_p[0] + [dt]
    step_names = ["z", "x0"] + (["u"] if nu else []) + with_p[1] + ["dt"]
    flows = ([ca.vertcat(step(scheme.flows.input_work), step(scheme.flows.dissipated))]
             if scheme.has_energy_flows else [])

    specs: dict[str, tuple] = {}

    def fn(name, inputs, input_names, outputs, output_names):
        """Record a function (built at the end, once its parameter-only parts are known)."""
        specs[name] = (inputs, input_names, outputs, output_names)
        return name

    def sensitivity_functions() -> tuple[ca.Function, ca.Function]:
        """The controller's state is s = (phi, omega); x0 = X(s0, p) (initial_state), s1 =
        S(x1, p) (outputs). With F(z*, x0, u, p) = 0, dz*/d(s0, u, p) = -J^-1 [F_x0 X_s, F_u,
        F_x0 X_p + F_p] (the C code solves it with one LU of J at z*), and ds1/d(s0, u, p) =
        S_x1 (x1_z dz* + [x1_x0 X_s, x1_u, x1_x0 X_p + x1_p]) + [0, 0, S_p]. X is evaluated at
        s0 = S(x0, p), so the functions take x0 as the step does."""
        s_of_x0 = ca.vertcat(*joint_space(x0)[:2])
        joint_state = ca.vertcat(phi, phidot)
        state_maps = ca.Function("X", [phi, phidot, p],
                                 [ca.jacobian(initial_state, joint_state),
                                  ca.jacobian(initial_state, p)])
        x_s, x_p = state_maps(s_of_x0[:n], s_of_x0[n:], p)
        s1 = ca.vertcat(*joint_space(x1)[:2])
        f_x0 = ca.jacobian(residual, x0)
        rhs = ca.densify(ca.horzcat(ca.mtimes(f_x0, x_s), ca.jacobian(residual, u),
                                    ca.mtimes(f_x0, x_p) + ca.jacobian(residual, p)))
        s1_z = ca.densify(ca.jacobian(s1, z))
        s1_x0 = ca.jacobian(s1, x0)
        s1_s0 = ca.densify(ca.mtimes(s1_x0, x_s))
        s1_u = ca.densify(ca.jacobian(s1, u))
        s1_p = ca.densify(ca.mtimes(s1_x0, x_p) + ca.jacobian(s1, p))
        outputs = [s1_z, s1_s0] + ([s1_u] if nu else []) + ([s1_p] if n_p else [])
        names = ["s1_z", "s1_s0"] + (["s1_u"] if nu else []) + (["s1_p"] if n_p else [])
        return (fn("sensitivity_rhs", step_args, step_names, [rhs], ["R"]),
                fn("sensitivity_map", step_args, step_names, outputs, names))

    def state_chain_functions() -> tuple[ca.Function, ca.Function, ca.Function]:
        """The stage Jacobians in the whole state x (SchemeFunctions.joint_maps): with
        F(z*, x0, u, p) = 0, dx1/d(x0, u, p) = x1_z dz* + [x1_x0, x1_u, x1_p] and
        dz* = -J^-1 [F_x0, F_u, F_p]; the composed step's ds1/ds0 = S_x1 D X_s."""
        rhs = ca.densify(ca.horzcat(ca.jacobian(residual, x0), ca.jacobian(residual, u),
                                    ca.jacobian(residual, p)))
        outputs = [ca.densify(ca.jacobian(x1, z)), ca.densify(ca.jacobian(x1, x0))]
        names = ["x1_z", "x1_x0"]
        if nu:
            outputs.append(ca.densify(ca.jacobian(x1, u)))
            names.append("x1_u")
        if n_p:
            outputs.append(ca.densify(ca.jacobian(x1, p)))
            names.append("x1_p")
        joint_state = ca.vertcat(phi, phidot)
        state_maps = ca.Function("X", [phi, phidot, p],
                                 [ca.jacobian(initial_state, joint_state),
                                  ca.jacobian(initial_state, p)])
        s_of_x0 = ca.vertcat(*joint_space(x0)[:2])
        x_s, x_p = state_maps(s_of_x0[:n], s_of_x0[n:], p)
        s1 = ca.vertcat(*joint_space(x)[:2])
        maps = [ca.densify(x_s), ca.densify(ca.jacobian(s1, x))]
        map_names = ["x0_s0", "s1_x1"]
        if n_p:
            maps += [ca.densify(x_p), ca.densify(ca.jacobian(s1, p))]
            map_names += ["x0_p", "s1_p"]
        return (fn("sensitivity_rhs", step_args, step_names, [rhs], ["R"]),
                fn("sensitivity_map", step_args, step_names, outputs, names),
                fn("joint_maps", [x0, x] + with_p[0], ["x0", "x1"] + with_p[1], maps,
                   map_names))

    sensitivity_rhs = sensitivity_map = joint_maps = None
    if sensitivities and chains_state(scheme):
        sensitivity_rhs, sensitivity_map, joint_maps = state_chain_functions()
    elif sensitivities:
        sensitivity_rhs, sensitivity_map = sensitivity_functions()
    margins = None
    if scheme.segments.vectors.shape[0]:
        # The segments at the scene's own numbers: their tolerances are the scene's.
        tolerances = ca.DM(list(scheme.segments.tolerances))
        before = ca.reshape(_vector(state_translator(x0), scheme.segments.vectors), 2, -1)
        after = ca.reshape(_vector(state_translator(x), scheme.segments.vectors), 2, -1)
        lengths_before = ca.sqrt(ca.sum1(before ** 2)).T
        lengths_after = ca.sqrt(ca.sum1(after ** 2)).T
        turn = ca.sum1(before * after).T / (lengths_before * lengths_after)
        margins = fn("segment_margins", [x0, x] + with_p[0], ["x0", "x1"] + with_p[1],
                     [ca.vertcat(lengths_after / tolerances, turn)], ["margins"])
    check = None
    if scheme.maps.kinetic_energy is not None:
        at = state_translator(x)
        check = fn("energy_check", [x] + with_p[0], ["x"] + with_p[1],
                   [ca.vertcat(at(scheme.maps.energy), at(scheme.maps.kinetic_energy))], ["H_T"])
    holding = None
    if scheme.maps.holding_torques is not None:
        torques = _vector(SympyToCasadi({**dict(zip(scheme.maps.initial_angles, ca.vertsplit(phi))),
                                         **parameter_bindings}, parameters),
                          scheme.maps.holding_torques)
        holding = fn("holding_torques", [phi] + with_p[0], ["phi"] + with_p[1], [torques],
                     ["tau"])
    factors, pattern = None, None
    if scheme.step.arm_space is not None:
        arm_factors, pattern = _arm_factors(scheme, bindings, parameters, step, z)
        factors = fn("newton_factors", step_args, step_names, [residual, arm_factors],
                     ["F", "factors"])
    names = dict(
        residual=fn("residual", step_args, step_names, [residual], ["F"]),
        residual_jacobian=fn("residual_jacobian", step_args, step_names,
                             [residual, residual if jacobian is None else jacobian],
                             ["F", "J"]),
        predictor=fn("predictor", [x0] + with_p[0] + [dt], ["x0"] + with_p[1] + ["dt"],
                     [_predictor(scheme, x0, dt, state_translator)], ["z"]),
        next_state=fn("next_state", step_args, step_names, [x1] + flows,
                      ["x1"] + (["flows"] if flows else [])),
        outputs=fn("outputs", [x] + with_p[0], ["x"] + with_p[1], list(joint_space(x)),
                   ["phi", "omega", "energy", "constraint"]),
        initial_state=fn("initial_state", [phi, phidot] + with_p[0],
                         ["phi", "phidot"] + with_p[1], [initial_state], ["x"]),
        sensitivity_rhs=sensitivity_rhs, sensitivity_map=sensitivity_map, joint_maps=joint_maps,
        holding_torques=holding, segment_margins=margins, energy_check=check,
        newton_factors=factors,
    )
    built = _build(specs, prefix, p, options, directions)
    return SchemeFunctions(**{field: None if name is None else built[name]
                              for field, name in names.items()},
                           parameters=built.get(PARAMETERS_FUNCTION), arm_pattern=pattern)


def _arm_factors(scheme: DiscreteScheme, bindings: dict, parameters: list,
                 step: SympyToCasadi, z: ca.SX) -> tuple[ca.SX, tuple]:
    """The factors of es's Newton matrix (ArmSpace) as one vector in the step's inputs, and
    H's pattern. h and c are translated with the arm increments w as free symbols, so that
    dh/dw and dc/dw are CasADi's sparse symbolic Jacobians (a few entries per link), then w is
    put back as the function of z it is. Raises ValueError if h or c depend on dv other than
    through w, or the blocks of G_mu and G_c are not one 2-vector per link."""
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
    forces = _vector(local, arms.forces)
    rows = _vector(local, scheme.step.residual[2 * n:, :])
    if ca.jacobian(ca.vertcat(forces, rows), z[:2 * n]).nnz():
        raise ValueError("es: the arm forces depend on dv other than through w = B dv")
    H = ca.jacobian(forces, w)
    g_mu = ca.jacobian(forces, z[2 * n:])
    g_c = ca.jacobian(rows, w)
    for name, block, shape in (("G_mu", g_mu, lambda r, c: r // 2 == c),
                               ("G_c", g_c, lambda r, c: c // 2 == r)):
        if not all(shape(r, c) for r, c in zip(*block.sparsity().get_triplet())):
            raise ValueError(f"es: {name} is not one 2-vector per link")
    g_mu = ca.vertcat(*[g_mu[r, r // 2] for r in range(2 * n)])
    g_c = ca.vertcat(*[g_c[c // 2, c] for c in range(2 * n)])
    local_values = ca.vertcat(*H.nonzeros(), g_mu, g_c)
    local_values = ca.substitute(local_values, w,
                                 ca.vertcat(*[step(symbol) for symbol in arms.arm_increments]))
    factors = ca.vertcat(local_values, _vector(step, arms.masses), _vector(step, arms.maps))
    rows_h, columns_h = H.sparsity().get_triplet()
    return factors, (tuple(rows_h), tuple(columns_h))


#: The name of the generated function that computes the derived parameters q from p.
PARAMETERS_FUNCTION = "parameters"


def _build(specs: dict[str, tuple], prefix: str, p: ca.SX, options: dict,
           directions: int | None = None) -> dict:
    """The recorded functions as CasADi Functions. With run-time parameters p, every
    subexpression that depends on p alone is hoisted out of them (CasADi's extract_parametric,
    one pass over all of them, so a subexpression they share is one entry): a function
    `parameters` computes those, q = Q(p), and every other function takes q in p's place. The
    C code evaluates Q once when p changes instead of in every residual of every step.
    directions: the Newton Jacobian's forward directions per pass (None: unrolled)."""
    def function(name, inputs, input_names, outputs, output_names):
        if name == "residual_jacobian" and directions:   # z is the first input
            return jacobian_by_directions(f"{prefix}_model_{name}", inputs, input_names,
                                          outputs[0], 0, directions, options)
        return ca.Function(f"{prefix}_model_{name}", inputs, outputs, input_names, output_names,
                           options)

    if p.shape[0] == 0:
        return {name: function(name, *spec) for name, spec in specs.items()}
    order = [(name, index) for name, spec in specs.items() for index in range(len(spec[2]))]
    expressions = [specs[name][2][index] for name, index in order]
    hoisted, symbols, values = ca.extract_parametric(expressions, p,
                                                     {"extract_trivial": True, "prefix": "q_"})
    q = ca.vertcat(*symbols) if symbols else ca.SX(0, 1)
    rewritten: dict[str, list] = {name: [] for name in specs}
    for (name, _), expression in zip(order, hoisted):
        rewritten[name].append(expression)
    built = {PARAMETERS_FUNCTION: function(PARAMETERS_FUNCTION, [p], ["p"],
                                           [ca.vertcat(*values) if values else ca.SX(0, 1)],
                                           ["q"])}
    for name, (inputs, input_names, _, output_names) in specs.items():
        inputs = [q if item is p else item for item in inputs]
        input_names = ["q" if item == "p" else item for item in input_names]
        built[name] = function(name, inputs, input_names, rewritten[name], output_names)
    return built


def _predictor(scheme: DiscreteScheme, x0: ca.SX, dt: ca.SX, state_translator) -> ca.SX:
    """The first Newton guess; it may use the output_solve symbols (vi: w = M^-1 p)."""
    if not any(scheme.step.predictor):
        return ca.SX.zeros(scheme.step.unknowns.shape[0], 1)
    return _vector(state_translator(x0, {scheme.step.dt: dt}), scheme.step.predictor)
