"""What every time-stepping scheme hands to code generation: a plain, immutable value.

A scheme is a state x_k, unknowns z, a residual F(z; x_k, dt) = 0 solved by Newton's method, the
map to the next state, a predictor for the first Newton guess, and the maps between its state
and joint space. Templates, Newton loop, build and runtime are shared by all schemes: they see
only this value. It is the only product of derivation: code generation translates it and never
asks the physics again (holding torques, segment tolerances and the documentation of the
scheme are on it too).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_EVERY_ITERATE
from ...scene import Scene
from ...scene.kinematics import RUN_SEGMENT_RELATIVE_TOLERANCE, run_segment_tolerance
from ...spatial.values import SpatialScene
from ..joint_model import angle_directions, joint_space_potential


@dataclass(frozen=True)
class Layout:
    """The layout of one vector that crosses the C boundary: a name and a meaning per entry."""

    entries: tuple[str, ...]
    description: str

    def __len__(self) -> int:
        return len(self.entries)


@dataclass(frozen=True)
class ArmSpace:
    """The factors of es's Newton matrix (docs/model.md, section 18).

    es's momentum balance is M dv + dt m g + B^T h(w, mu) and its constraint rows are c(w),
    with M the COM masses, B the constant map q -> arms d_k = x_k - X_k and w = B dv. h and c
    are local in the arms, so the Jacobian [[M + B^T H B, B^T G_mu], [G_c B, 0]] is known from
    H = dh/dw (banded), G_mu = dh/dmu and G_c = dc/dw (2 entries per link each), the masses
    and the maps A_k = L_k R_k of the recursion X_{k+1} = X_k + A_k d_k; the C code solves it
    in O(n^2) (chaingen_arm_solve.h) instead of forming and factorising it densely."""

    arm_increments: ImmutableMatrix   # w: 2n symbols defined in `definitions`, link by link
    forces: ImmutableMatrix           # h: 2n entries, link by link
    masses: ImmutableMatrix           # m_k
    maps: ImmutableMatrix             # A_k = L_k R_k, row-major, 4 entries per link
    # h with the springs' K-point average alone (EsStep.newton_forces): the chord's Newton
    # matrix is taken of it (chord_factors); None: of `forces`
    newton_forces: ImmutableMatrix | None = None


@dataclass(frozen=True)
class NodeSpace:
    """A residual that is a function of z and the outputs of one local function evaluated at
    several nodes (es's Galerkin step, docs/model.md section 16): node g's outputs
    o_g = N(y_g, u, p) with the same N at every node, y_g affine in z. Then
    dF/dz = F_z + sum_g F_o_g N'(y_g) Y_g, with F_z, F_o_g and Y_g = dy_g/dz sparse, and N' the
    Jacobian of one node (m x m): generated once, evaluated at each node, instead of every
    column of dF/dz carrying its tangent through every node. A few scalars r of the
    definitions through which F depends on all of z and the outputs (es's energy correction)
    are taken apart: F_r dr/dz, dr/dz through the nodes as a few rows."""

    inputs: tuple[ImmutableMatrix, ...]    # y_g: symbols defined in `definitions`, m per node
    outputs: tuple[ImmutableMatrix, ...]   # o_g: symbols defined in `definitions`, per node
    scalars: tuple[sp.Symbol, ...] = ()    # r: symbols defined in `definitions`


@dataclass(frozen=True)
class FlowDescription:
    """How a scheme measures the energy flows of a step, and the balance they satisfy
    (docs/model.md, section 7); written into the generated header."""

    input_work: str
    dissipated: str
    balance: str


@dataclass(frozen=True)
class SchemeMetadata:
    """What a scheme is: its method, the quadrature it runs with, the order of its step and
    the stages' step fractions (chaingen.symbolic.composition: order 2 is the scheme's own
    step, a single stage), and one sentence for the package's documentation."""

    method: str
    quadrature: int | None             # Gauss-Legendre points, None where K plays no role
    summary: str                       # one sentence: what the scheme is
    # What the quadrature K integrates, for the package's label (None: the spring terms by K
    # Gauss-Legendre points, es's COM step).
    quadrature_rule: str | None = None
    order: int = 2
    composition: tuple[float, ...] = (1.0,)
    # es's discrete gradient of the springs ("exact", "quadrature" or "chain"), None where it
    # plays no role (chaingen.scene.solver_rules.gradient_used).
    gradient: str | None = None


@dataclass(frozen=True)
class StepSystem:
    """One step as Newton's method solves it: unknowns z, a residual F(z; x_k, u, p, dt) = 0,
    the next state x_{k+1}(z; x_k, dt), the first guess, and the package's Newton defaults."""

    dt: sp.Symbol
    unknowns: ImmutableMatrix          # symbols of z
    residual: ImmutableMatrix          # F(z; x_k, dt), one entry per unknown
    next_state: ImmutableMatrix        # x_{k+1}(z; x_k, dt)
    predictor: ImmutableMatrix         # first Newton guess z(x_k, dt)
    unknowns_layout: Layout
    residual_description: str
    # Intermediate quantities of the step, (symbol, expression) in order of definition: each
    # expression uses the step's inputs (z, x_k, u, dt) and earlier symbols, and residual,
    # next_state and the flows may use the symbols. They keep a large chain's expressions as
    # a sequence of small ones (model.md's spring segments at each quadrature node), which code
    # generation translates once and shares, instead of SymPy expanding them into every use.
    definitions: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    # The Newton Jacobian reuse the package defaults to (a JACOBIAN_* mode of the contract).
    jacobian_reuse: int = JACOBIAN_EVERY_ITERATE
    # Other Newton defaults of the package that differ from the contract's, (name, value).
    newton_overrides: tuple[tuple[str, float], ...] = ()
    # The factors of the Newton matrix where the package solves it by them (es at large n),
    # else None: dense LU of dF/dz.
    arm_space: ArmSpace | None = None
    # Where dF/dz is evaluated by forward directions (model.md 17): the sizes of consecutive
    # blocks of z, each differentiated by its own forward derivative, which carries tangents
    # from that block alone (es's Galerkin step: its angles, which move every quantity of a
    # node, then its momenta, which leave the frames and the articulated inertias alone).
    # Empty: z as one block.
    jacobian_blocks: tuple[int, ...] = ()
    # Where dF/dz is evaluated through a local function of several nodes (NodeSpace), that
    # structure; None: by the residual as a whole.
    node_space: NodeSpace | None = None
    # A matrix A ~ dF/dz that Newton's method takes in place of dF/dz (its entries in the
    # step's inputs and definitions, row by row: A[i, j] at i * nz + j), where it is much
    # cheaper and contracts almost as well (spatial es: 2 P^T M P / dt, docs/model.md 4.8);
    # the exact dF/dz stays for the step sensitivities and `check`. None: dF/dz.
    newton_matrix: ImmutableMatrix | None = None


@dataclass(frozen=True)
class StateMaps:
    """The scheme's state x and its maps: to joint space and the diagnostics (outputs), from
    joint space (initial_state), and the holding torques at a posture."""

    state: ImmutableMatrix             # symbols of x_k
    state_layout: Layout
    joint_angles: ImmutableMatrix      # phi(x), relative angles wrapped to (-pi, pi]
    joint_velocities: ImmutableMatrix  # omega(x), relative angular velocities
    energy: sp.Expr                    # H(x) = T + V
    constraint_residuals: ImmutableMatrix  # structural errors of x; C reports max |.|
    initial_angles: ImmutableMatrix    # symbols phi of initial_state
    initial_velocities: ImmutableMatrix  # symbols phidot of initial_state
    initial_state: ImmutableMatrix     # x(phi, phidot)
    # The definitions (as StepSystem's) of the expressions of the state alone (joint_angles,
    # joint_velocities, energy, constraint_residuals, segment vectors, predictor), in the
    # state and p; and of initial_state, in initial_angles,
    # initial_velocities and p. A joint-space chain's recursions (chaingen.symbolic.recursion)
    # keep these O(n) too.
    state_definitions: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    initial_definitions: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    # dV/dphi in the symbols initial_angles: the joint torques that hold the chain still at a
    # posture (gravity and springs), a controller's feed-forward. Actuated scenes only.
    holding_torques: ImmutableMatrix | None = None
    # Whether the joint-space state s = (phi, omega) determines the scheme's state x along a
    # run (x = initial_state(outputs(x))): then the step sensitivities of a composed step
    # are the chain rule of its stages' in joint space. es's x carries a normal velocity
    # component s does not see.
    state_from_joint_space: bool = True
    # T(x), for the check of a converged step against the energy balance (docs/model.md,
    # section 13) of a scheme that does not keep it exactly (vi, midpoint); None: no check.
    kinetic_energy: sp.Expr | None = None


@dataclass(frozen=True)
class EnergyFlows:
    """Inputs (model.md 7): torques u of the scene's actuated joints, constant over a step (the
    residual and next_state may depend on them; empty for an unactuated scene), and the energy
    flows of one step, functions of (z, x0, u, dt): the work of u and the energy dissipated by
    joint damping (>= 0); zero for a scene with neither."""

    inputs: ImmutableMatrix = ImmutableMatrix.zeros(0, 1)
    input_work: sp.Expr = sp.Integer(0)
    dissipated: sp.Expr = sp.Integer(0)
    description: FlowDescription | None = None   # None for a scene without energy flows
    # The torque each actuated joint applies over the step (issue 34, a scene with a [control]
    # table): NU expressions, in the scene's actuated order, in the step's inputs (z, x0, u, p,
    # dt; DiscreteScheme.step_inputs) and its definitions, evaluated at the converged z by the
    # package's control_torques. None for every scene without control: nothing is generated.
    applied_torques: ImmutableMatrix | None = None


@dataclass(frozen=True)
class SpringSegments:
    """Every spring segment P_{j+1} - P_j of the state as (dx, dy) pairs, watched during a run
    (model.md 2): a segment must not shrink to zero length nor pass through it in a step; the
    length under which each stops a run (m), and that length relative to the geometry's size
    (docs/model.md, section 12)."""

    vectors: ImmutableMatrix = ImmutableMatrix.zeros(0, 1)
    tolerances: tuple[float, ...] = ()
    relative_tolerance: float = RUN_SEGMENT_RELATIVE_TOLERANCE


@dataclass(frozen=True)
class RunParameters:
    """Run-time parameters: scene numbers left as symbols p (every other number is a constant
    folded into the code), with their key paths, units and the scene's own values."""

    symbols: ImmutableMatrix = ImmutableMatrix.zeros(0, 1)
    paths: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    values: tuple[float, ...] = ()


#: The records of a DiscreteScheme, by its field names.
RECORDS = {"metadata": SchemeMetadata, "step": StepSystem, "maps": StateMaps,
           "flows": EnergyFlows, "segments": SpringSegments, "run_parameters": RunParameters}
#: The flat names a scheme builder passes (DiscreteScheme.of) that are not their record
#: field's name: flat name -> (record, field).
_RENAMED = {"flow_description": ("flows", "description"),
            "segment_vectors": ("segments", "vectors"),
            "segment_tolerances": ("segments", "tolerances"),
            "segment_relative_tolerance": ("segments", "relative_tolerance"),
            "parameters": ("run_parameters", "symbols"),
            "parameter_paths": ("run_parameters", "paths"),
            "parameter_units": ("run_parameters", "units"),
            "parameter_values": ("run_parameters", "values")}
#: Every flat name of a scheme's fields: flat name -> (record, field).
FLAT_NAMES = {**{field.name: (record, field.name) for record, kind in RECORDS.items()
                 for field in dataclasses.fields(kind)
                 if (record, field.name) not in _RENAMED.values()}, **_RENAMED}


@dataclass(frozen=True, init=False)
class DiscreteScheme:
    """A scheme for one scene: the records it is made of. Code generation reads them by
    record (scheme.step.residual, scheme.maps.state_layout); a flat name (scheme.residual)
    reads the same field, and dataclasses.replace(scheme, residual=...) replaces it, for code
    written before the records (FLAT_NAMES)."""

    scene: Scene
    metadata: SchemeMetadata
    step: StepSystem
    maps: StateMaps
    flows: EnergyFlows = EnergyFlows()
    segments: SpringSegments = SpringSegments()
    run_parameters: RunParameters = RunParameters()

    def __init__(self, scene: Scene, metadata: SchemeMetadata, step: StepSystem,
                 maps: StateMaps, flows: EnergyFlows = EnergyFlows(),
                 segments: SpringSegments = SpringSegments(),
                 run_parameters: RunParameters = RunParameters(), **flat):
        records = {"metadata": metadata, "step": step, "maps": maps, "flows": flows,
                   "segments": segments, "run_parameters": run_parameters}
        changes: dict[str, dict] = {}
        for name, value in flat.items():
            if name not in FLAT_NAMES:
                raise TypeError(f"DiscreteScheme has no field {name!r}")
            record, field = FLAT_NAMES[name]
            changes.setdefault(record, {})[field] = value
        for record, values in changes.items():
            records[record] = dataclasses.replace(records[record], **values)
        object.__setattr__(self, "scene", scene)
        for record, value in records.items():
            object.__setattr__(self, record, value)

    @classmethod
    def of(cls, scene: Scene, **fields) -> DiscreteScheme:
        """The scheme of `scene` from its fields by their flat names (FLAT_NAMES), each put
        into its record."""
        records: dict[str, dict] = {record: {} for record in RECORDS}
        for name, value in fields.items():
            if name not in FLAT_NAMES:
                raise TypeError(f"DiscreteScheme.of: no field {name!r}")
            record, field = FLAT_NAMES[name]
            records[record][field] = value
        return cls(scene=scene, **{record: RECORDS[record](**values)
                                   for record, values in records.items()})

    def replaced(self, **fields) -> DiscreteScheme:
        """This scheme with fields, by their flat names, replaced in their records."""
        changes: dict[str, dict] = {}
        for name, value in fields.items():
            if name == "scene":
                continue
            record, field = FLAT_NAMES[name]
            changes.setdefault(record, {})[field] = value
        return dataclasses.replace(
            self, scene=fields.get("scene", self.scene),
            **{record: dataclasses.replace(getattr(self, record), **values)
               for record, values in changes.items()})

    def __getattr__(self, name: str):
        # Only names that normal lookup does not find (the flat names) get here.
        if name in FLAT_NAMES and "step" in self.__dict__:
            record, field = FLAT_NAMES[name]
            return getattr(self.__dict__[record], field)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def step_inputs(self) -> list[sp.Symbol]:
        """The inputs of the step's functions, in order: z, x_k, u, p, dt."""
        return (list(self.step.unknowns) + list(self.maps.state) + list(self.flows.inputs)
                + list(self.run_parameters.symbols) + [self.step.dt])

    def step_function(self, expressions):
        """A numpy function of the step_inputs' values that evaluates `expressions`, which may
        use the definitions. The definitions are evaluated in order, as the generated C does,
        not substituted into one another (for a long chain that takes SymPy minutes)."""
        return numpy_function(self.step_inputs, self.step.definitions, expressions)

    def state_function(self, expressions, extra=()):
        """A numpy function of (state, p, *extra) for state-only expressions, which may use
        the state_definitions."""
        return numpy_function(list(self.maps.state) + list(self.run_parameters.symbols)
                              + list(extra), self.maps.state_definitions, expressions)

    def initial_function(self):
        """The numpy function (phi, phidot, p) -> initial_state."""
        maps = self.maps
        return numpy_function(list(maps.initial_angles) + list(maps.initial_velocities)
                              + list(self.run_parameters.symbols), maps.initial_definitions,
                              maps.initial_state)

    @property
    def control_law(self) -> str | None:
        """The kind of the [control] law in the step: "discrete", or "sampled" (held from the
        step's start, its hold period the step: the model table's held_control, which keeps
        simulate to fixed steps, and the manifest's control_law); None without a law."""
        control = getattr(self.scene, "control", None)
        return None if control is None or self.flows.applied_torques is None else control.law

    @property
    def has_energy_flows(self) -> bool:
        """Whether energy can enter (inputs) or leave (damping, a constant or a parameter)."""
        return bool(self.flows.inputs.shape[0]) or self.flows.dissipated != 0

    def __post_init__(self) -> None:
        method = self.metadata.method
        if self.step.residual.shape[0] != self.step.unknowns.shape[0]:
            raise ValueError(f"{method}: {self.step.residual.shape[0]} residual entries for "
                             f"{self.step.unknowns.shape[0]} unknowns")
        if self.step.next_state.shape[0] != self.maps.state.shape[0]:
            raise ValueError(f"{method}: next_state does not match the state")


def numpy_function(inputs, definitions, expressions):
    """sp.lambdify of `expressions` over `inputs`, evaluating `definitions` (symbol, expression)
    in order first."""
    def eliminate(reduced):
        shared, reduced = sp.cse(reduced, symbols=sp.numbered_symbols("_shared"))
        return list(definitions) + shared, reduced

    return sp.lambdify(list(inputs), list(expressions), modules="numpy",
                       cse=eliminate if definitions else True)


def actuated_joints(scene: Scene | SpatialScene) -> tuple[int, ...]:
    """The 1-based actuated joints of a planar or a spatial scene, ascending."""
    return scene.actuated if isinstance(scene, SpatialScene) else scene.actuated_joints


def has_energy_flows(scene: Scene | SpatialScene) -> bool:
    """Whether energy can enter (actuation) or leave (damping) the chain."""
    return bool(actuated_joints(scene)) or any(link.damping for link in scene.links)


def input_symbols(scene: Scene | SpatialScene) -> ImmutableMatrix:
    """u: one torque symbol per actuated joint, in the scene's order."""
    return ImmutableMatrix(sp.symbols([f"tau{j}" for j in actuated_joints(scene)], real=True))


def joint_torques(scene: Scene | SpatialScene, inputs) -> list[sp.Expr]:
    """tau_i for every joint i: the input of an actuated joint, zero elsewhere."""
    torques = [sp.Integer(0)] * scene.n
    for joint, u in zip(actuated_joints(scene), inputs):
        torques[joint - 1] = u
    return torques


def segment_vectors(model) -> ImmutableMatrix:
    """(dx, dy) of every segment of every spring of a model, spring by spring."""
    return ImmutableMatrix([c for term in model.springs for d in term.segment_vectors for c in d])


def segment_tolerances(scene: Scene) -> tuple[float, ...]:
    """The run tolerance of every segment of segment_vectors, spring by spring."""
    return tuple(run_segment_tolerance(scene, spring)
                 for spring in scene.springs for _ in spring.joints)


def holding_torques(scene: Scene | SpatialScene, angles) -> ImmutableMatrix | None:
    """dV/dphi at the relative angles `angles` (symbols) for an actuated planar scene, else
    None: a spatial scene's package has no holding torques (the planar potential's closed
    form does not carry over; its example controller runs without them)."""
    if isinstance(scene, SpatialScene) or not scene.actuated_joints:
        return None
    potential = joint_space_potential(scene, angle_directions(angles))
    return ImmutableMatrix([potential]).jacobian(list(angles)).T


def common_fields(scene: Scene | SpatialScene, angles) -> dict:
    """The fields every scheme derives the same way from its scene (angles: the symbols of
    initial_angles)."""
    return {"holding_torques": holding_torques(scene, angles)}


def joint_space_state(scene: Scene | SpatialScene, angles, rates, energy) -> dict:
    """The fields of a scheme whose state is x = (phi, w), the relative joint angles `angles`
    (not wrapped) and rates `rates` (symbols), with energy H(x): its outputs, its start from
    joint space, its layout and common_fields. Minimal coordinates: no constraint residuals."""
    n = scene.n
    phi = ImmutableMatrix(sp.symbols(f"phi_init1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot_init1:{n + 1}", real=True))
    return dict(
        state=ImmutableMatrix.vstack(angles, rates),
        joint_angles=ImmutableMatrix([sp.atan2(sp.sin(p), sp.cos(p)) for p in angles]),
        joint_velocities=ImmutableMatrix(rates), energy=energy,
        constraint_residuals=ImmutableMatrix.zeros(0, 1),
        initial_angles=phi, initial_velocities=phidot,
        initial_state=ImmutableMatrix.vstack(phi, phidot),
        state_layout=Layout(
            tuple(f"phi_{i}" for i in range(1, n + 1)) + tuple(f"w_{i}" for i in range(1, n + 1)),
            "relative joint angles phi (rad, not wrapped), then joint rates w (rad/s)"),
        **common_fields(scene, phi))
