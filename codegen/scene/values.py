"""The values of a scene: frozen dataclasses of validated numbers (docs/scene-format.md).

A Scene is what the reader (chaingen.scene.reader) makes of a scene file; everything downstream
(symbolic model, schemes, C package) is a pure function of it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..runtime.interface import MAX_INITIAL_ANGLE as MAX_INITIAL_ANGLE
from ..runtime.interface import far_angle as _far_angle

# The rules of a request (methods, K, orders) are chaingen.scene.solver_rules'; named here too
# for the simulation defaults below and for the modules that import them from here.
from .solver_rules import GALERKIN_ORDER as GALERKIN_ORDER
from .solver_rules import METHODS as METHODS
from .solver_rules import ORDERS as ORDERS
from .solver_rules import QUADRATURE_RANGE as QUADRATURE_RANGE
from .solver_rules import quadrature_used as quadrature_used


def far_angle(path: str, angles) -> tuple[str, str, float] | None:
    """(key path, what is wrong, value) for the first of `angles` beyond MAX_INITIAL_ANGLE
    (the runtime's rule, chaingen.runtime.interface; SceneReader.fail's arguments), or None."""
    refused = _far_angle(angles)
    if refused is None:
        return None
    index, angle, what = refused
    return f"{path}[{index}]", what, angle


def c_identifier(name: str) -> str:
    """The C-safe form of a scene name: lower case, '-' replaced by '_'."""
    return name.lower().replace("-", "_")


@dataclass(frozen=True)
class LinkField:
    """One number of a link: its key in a scene file's [[links]] table, which is also its
    attribute of `Link` and its key path's last part (links[0].mass), its symbol in
    docs/model.md, section 1, its unit, and its default (None: required)."""

    key: str
    symbol: str          # with the link's 1-based index i: "m_{i}", or "r_{i+1}"
    unit: str
    default: float | None
    joint: bool = False  # a number of joint i (damping), named so in messages, not of link i

    def meaning(self, i: int) -> str:
        """How a message names this number of link i (1-based): "m_2 in kg, link 2"."""
        symbol = self.symbol.replace("{i+1}", str(i + 1)).replace("{i}", str(i))
        return f"{symbol} in {self.unit}, {'joint' if self.joint else 'link'} {i}"


#: The numbers of a link, in the order of `Link`'s fields and of a scene file's keys
#: (docs/scene-format.md): the reader, `Link`, the key paths of chaingen.scene.parameters and
#: the scene document all read this table.
LINK_FIELDS = (
    LinkField("mass", "m_{i}", "kg", None),
    LinkField("inertia", "J_{i}", "kg m^2", None),
    LinkField("length", "L_{i}", "m", None),
    LinkField("com", "a_{i}", "m", None),
    LinkField("com_normal", "b_{i}", "m", 0.0),
    LinkField("fastening", "r_{i+1}", "m", 0.0),
    LinkField("damping", "d_{i}", "N m s/rad", 0.0, joint=True),
)


@dataclass(frozen=True)
class Link:
    """Link i of docs/model.md, section 1 (SI units)."""

    mass: float          # m_i > 0
    inertia: float       # J_i >= 0 about the COM
    length: float        # L_i > 0, joint i to joint i+1
    com: float           # a_i, along the link from the proximal joint
    com_normal: float    # b_i, normal to the link
    fastening: float     # r_{i+1}, normal offset of the fastening at the distal joint
    damping: float       # d_i >= 0, viscous damping of joint i
    # The fields are LINK_FIELDS' keys, in its order (tests/test_tables.py).


@dataclass(frozen=True)
class Spring:
    """A linear spring over joints first..last (1-based, docs/model.md, section 2)."""

    first: int
    last: int
    stiffness: float
    rest_length: float
    offsets: tuple[float, ...] | None   # r of fastenings first..last+1, or None: the chain's

    @property
    def is_multi_articular(self) -> bool:
        return self.last > self.first

    @property
    def joints(self) -> tuple[int, ...]:
        return tuple(range(self.first, self.last + 1))


#: The control laws of a [control] table: "discrete", the discrete-gradient law solved inside
#: the step (es and midpoint), and "sampled", the same law held from the step's start.
CONTROL_LAWS = ("discrete", "sampled")


@dataclass(frozen=True)
class Control:
    """Energy shaping and damping injection on the actuated joints (docs/controllers.md,
    "Passivity-based control"): the shaping potential V_s = 1/2 sum k_a (phi_a - phi*_a)^2
    minus, with `compensate`, the scene's own potential at the actuated angles (the others at
    their target), and the injected torque -D_a phidot_a."""

    target: tuple[float, ...]      # phi*_i (rad), one per joint
    stiffness: tuple[float, ...]   # k_a >= 0 (N m/rad), one per actuated joint
    damping: tuple[float, ...]     # D_a >= 0 (N m s/rad), one per actuated joint
    compensate: bool = True
    law: str = CONTROL_LAWS[0]


@dataclass(frozen=True)
class Simulation:
    """Defaults for `simulate`; command-line options override them."""

    method: str = METHODS[0]
    quadrature: int = 3
    dt: float = 0.01
    t_end: float = 10.0
    order: int = ORDERS[0]
    rtol: float = 0.0     # adaptive steps' local error tolerances; both 0: fixed steps of dt
    atol: float = 0.0
    gradient: str = "exact"   # es's discrete gradient of the springs (solver_rules.GRADIENTS)


@dataclass(frozen=True)
class Scene:
    """One chain, its springs, its initial state and its simulation defaults: the validated
    numbers of a scene file (docs/scene-format.md). Everything downstream is a function of it."""

    name: str
    gravity: float
    base_fastening: float                  # r_1
    links: tuple[Link, ...]
    springs: tuple[Spring, ...]
    initial_angles: tuple[float, ...]      # phi_i (rad)
    initial_velocities: tuple[float, ...]  # phidot_i (rad/s)
    simulation: Simulation
    actuated_joints: tuple[int, ...] = ()  # 1-based joints driven by an input torque, ascending
    control: Control | None = None         # a [control] table: the actuated joints' control law
    #: es below order 6 averages the springs' gradient over K Gauss-Legendre points (model.md 4).
    spring_quadrature: ClassVar[bool] = True

    @property
    def n(self) -> int:
        return len(self.links)

    def chain_fastenings(self) -> tuple[float, ...]:
        """r_1 .. r_{n+1}: the base's fastening, then each link's distal one."""
        return (self.base_fastening,) + tuple(link.fastening for link in self.links)

    def spring_fastenings(self, spring: Spring) -> tuple[float, ...]:
        """r of the fastenings P_first .. P_{last+1} that `spring` runs through."""
        if spring.offsets is not None:
            return spring.offsets
        return self.chain_fastenings()[spring.first - 1: spring.last + 1]

    @property
    def c_name(self) -> str:
        """The name as used in C identifiers and file names (see `c_identifier`)."""
        return c_identifier(self.name)
