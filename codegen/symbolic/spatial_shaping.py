"""The shaping potential of a controlled spatial scene and its exact discrete gradient in the joint
angles (docs/controllers.md, "Passivity-based control"; the planar construction is
chaingen.symbolic.shaping).

A spatial chain's rotations are R_i = R_{i-1} (A_i + sin(phi_i) B_i + cos(phi_i) C_i)
(spatial_recursion.joint_rotation_factors): every position, COM and route point is multilinear
in the pairs e_i = (cos phi_i, sin phi_i), and gravity's potential is linear in the positions.
For a multilinear f, the telescoping sum over the joints in order,

    f(e^1) - f(e^0) = sum_j df/de_j (e^1_1..e^1_{j-1}, e^0_{j+1}..e^0_n) (e^1_j - e^0_j),

holds exactly (f is affine in e_j, so its difference in e_j alone is the derivative times the
difference), and so does the same sum in the reverse order; their mean is symmetric in time.
With e^1_j - e^0_j = sinc(dphi_j / 2) (-sin phi_mean, cos phi_mean) dphi_j exactly, this gives an
exact discrete gradient of gravity, and of each spring's segment vectors, whose lengths and
energy then follow the planar identities. The derivatives along e_j are carried through the
recursion by hand (forward mode): nothing is differentiated symbolically.
"""
from __future__ import annotations

import sympy as sp

from ..spatial.values import SpatialScene
from .com_model import number
from .shaping import offset, sinc
from .spatial_recursion import ZERO, add, apply, constant, dot, joint_rotation_factors, scale


def matrix_product(a, b):
    """a b of 3 x 3 matrices as rows."""
    return tuple(tuple(dot(a[r], [b[m][k] for m in range(3)]) for k in range(3))
                 for r in range(3))


class Chain:
    """The links' rotations and origins at joint pairs (c_i, s_i), and optionally their
    derivatives along one joint's pair (`joint`, 1-based, with the tangent (dc, ds))."""

    def __init__(self, scene: SpatialScene, pairs, joint: int | None = None, tangent=None):
        self.scene = scene
        rotation = derivative = None    # R_0 = 1, dR_0 = 0
        origin, velocity = ZERO, ZERO
        self.rotations, self.origins, self.tangents, self.moving = [], [], [], []
        for i, (link, (c, s)) in enumerate(zip(scene.links, pairs), start=1):
            xyz = constant(link.joint.xyz)
            if rotation is None:
                origin = xyz
            else:
                origin = add(origin, apply(rotation, xyz))
                if derivative is not None:
                    velocity = add(velocity, apply(derivative, xyz))
            A, B, C = joint_rotation_factors(link.joint)
            relative = tuple(tuple(A[r][k] + s * B[r][k] + c * C[r][k] for k in range(3))
                             for r in range(3))
            turned = relative if rotation is None else matrix_product(rotation, relative)
            if derivative is not None:
                derivative = matrix_product(derivative, relative)
            if i == joint:
                dc, ds = tangent
                change = tuple(tuple(ds * B[r][k] + dc * C[r][k] for k in range(3))
                               for r in range(3))
                own = change if rotation is None else matrix_product(rotation, change)
                derivative = own if derivative is None else tuple(
                    add(row, other) for row, other in zip(derivative, own))
            rotation = turned
            self.rotations.append(rotation)
            self.origins.append(origin)
            self.tangents.append((derivative, velocity))

    def point(self, link: int, point) -> tuple:
        """A point fixed on `link` (0: the base), in the world."""
        point = constant(point)
        if link == 0:
            return point
        return add(self.origins[link - 1], apply(self.rotations[link - 1], point))

    def point_tangent(self, link: int, point) -> tuple:
        """The derivative of `point` along the chain's tangent (zero inboard of its joint)."""
        if link == 0:
            return ZERO
        derivative, velocity = self.tangents[link - 1]
        out = velocity
        if derivative is not None:
            out = add(out, apply(derivative, constant(point)))
        return out



def gravity_energy(scene: SpatialScene, chain: Chain) -> sp.Expr:
    gravity = constant(scene.gravity)
    return -sp.Add(*(number(link.mass) * dot(gravity, chain.point(i, link.com))
                     for i, link in enumerate(scene.links, start=1)))


def gravity_tangent(scene: SpatialScene, chain: Chain) -> sp.Expr:
    gravity = constant(scene.gravity)
    return -sp.Add(*(number(link.mass) * dot(gravity, chain.point_tangent(i, link.com))
                     for i, link in enumerate(scene.links, start=1)))


def segments(scene: SpatialScene, chain: Chain, tangents: bool = False) -> list:
    """Per spring, the vectors of its route's segments (or their tangents)."""
    out = []
    for spring in scene.springs:
        at = chain.point_tangent if tangents else chain.point
        points = [at(p.link, p.point) for p in spring.route]
        out.append([add(b, scale(-1, a)) for a, b in zip(points, points[1:])])
    return out


def potential(scene: SpatialScene, angles) -> sp.Expr:
    """V (gravity and springs) at the joint angles `angles`."""
    chain = Chain(scene, [(sp.cos(a), sp.sin(a)) for a in angles])
    energy = gravity_energy(scene, chain)
    for spring, vectors in zip(scene.springs, segments(scene, chain)):
        length = sp.Add(*(sp.sqrt(dot(v, v)) for v in vectors))
        energy += number(spring.stiffness) / 2 * (length - number(spring.rest_length)) ** 2
    return energy



def _angles(scene: SpatialScene, actuated_angles) -> list:
    """Every joint's angle of the compensation term: the actuated ones given, the rest at
    their target."""
    angles = [number(t) for t in scene.control.target]
    for joint, value in zip(scene.actuated, actuated_angles):
        angles[joint - 1] = value
    return angles


def shaping_potential(scene: SpatialScene, actuated_angles) -> sp.Expr:
    """V_s = 1/2 sum k_a (phi_a - phi*_a)^2 - c V(phi_A, phi*_U)."""
    control = scene.control
    value = sp.Add(*(number(k) / 2 * offset(phi, control.target[joint - 1]) ** 2
                     for joint, k, phi in zip(scene.actuated, control.stiffness,
                                              actuated_angles)))
    if control.compensate:
        value -= potential(scene, _angles(scene, actuated_angles))
    return value


def discrete_shaping_gradient(scene: SpatialScene, start, increments, defs) -> list:
    """G with G . increments = V_s(start + increments) - V_s(start) identically (module
    docstring); with zero increments, dV_s/dphi_a at `start`."""
    control = scene.control
    actuated = scene.actuated
    gradient = [number(k) * (offset(phi, control.target[joint - 1]) + d / 2)
                for joint, k, phi, d in zip(actuated, control.stiffness, start, increments)]
    if not control.compensate:
        return gradient
    begin = _angles(scene, start)
    end = _angles(scene, [phi + d for phi, d in zip(start, increments)])
    pairs0, pairs1 = [], []
    for j, (a, b) in enumerate(zip(begin, end), start=1):
        pairs0.append((defs.define(f"sshape_c0_{j}", sp.cos(a)),
                       defs.define(f"sshape_s0_{j}", sp.sin(a))))
        pairs1.append((defs.define(f"sshape_c1_{j}", sp.cos(b)),
                       defs.define(f"sshape_s1_{j}", sp.sin(b))) if b != a else pairs0[-1])
    chain0, chain1 = Chain(scene, pairs0), Chain(scene, pairs1)
    tensions, units = [], []
    for s, (spring, v0s, v1s) in enumerate(zip(scene.springs, segments(scene, chain0),
                                               segments(scene, chain1))):
        l0s, l1s, spring_units = [], [], []
        for j, (v0, v1) in enumerate(zip(v0s, v1s)):
            v0 = [defs.define(f"sshape_v{s}_{j}_0{x}", c) for x, c in zip("xyz", v0)]
            v1 = [defs.define(f"sshape_v{s}_{j}_1{x}", c) for x, c in zip("xyz", v1)]
            l0 = defs.define(f"sshape_l{s}_{j}_0", sp.sqrt(dot(v0, v0)))
            l1 = defs.define(f"sshape_l{s}_{j}_1", sp.sqrt(dot(v1, v1)))
            l0s.append(l0)
            l1s.append(l1)
            spring_units.append([defs.define(f"sshape_u{s}_{j}{x}", (a + b) / (l0 + l1))
                                 for x, a, b in zip("xyz", v0, v1)])
        tensions.append(defs.define(f"sshape_tension{s}", number(spring.stiffness) * (
            (sp.Add(*l0s) + sp.Add(*l1s)) / 2 - number(spring.rest_length))))
        units.append(spring_units)
    for index, (joint, d) in enumerate(zip(actuated, increments)):
        middle = begin[joint - 1] + d / 2
        factor = defs.define(f"sshape_sinc{joint}", sinc(d / 2))
        tangent = (defs.define(f"sshape_dc{joint}", -factor * sp.sin(middle)),
                   defs.define(f"sshape_ds{joint}", factor * sp.cos(middle)))
        total = sp.Integer(0)
        for order in ("forward", "backward"):
            mixed = [(pairs1 if (i < joint) == (order == "forward") else pairs0)[i - 1]
                     for i in range(1, scene.n + 1)]
            chain = Chain(scene, mixed, joint, tangent)
            part = gravity_tangent(scene, chain)
            for tension, spring_units, moving in zip(tensions, units,
                                                     segments(scene, chain, tangents=True)):
                part += tension * sp.Add(*(dot(u, m) for u, m in zip(spring_units, moving)))
            total += part / 2
        gradient[index] -= defs.define(f"sshape_G{joint}", total)
    return gradient
