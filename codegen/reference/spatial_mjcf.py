"""MJCF (MuJoCo XML) of a spatial scene's chain: MuJoCo as the second reference of the spatial
dynamics (docs/spatial-mujoco.md), beside Pinocchio.

MuJoCo represents a SpatialScene (codegen/spatial/values.py) exactly:

- body i carries link i, nested in body i - 1 (body 1 in the world body); it sits at joint i's
  origin: ``pos="x y z"`` and ``euler="roll pitch yaw"`` read with ``<compiler
  eulerseq="XYZ">``, MuJoCo's extrinsic rotations about the parent's fixed x, then y, then z
  axis, which is URDF's R = Rz(yaw) Ry(pitch) Rx(roll) (MuJoCo's default "xyz" is intrinsic:
  Rx Ry Rz, another rotation);
- a hinge at the body origin about the joint's axis (in the joint frame, which is the body
  frame), so qpos[i-1] is q_i and the body frame is the link frame;
- ``<inertial pos="com" mass="m" fullinertia="ixx iyy izz ixy ixz iyz"/>``: MuJoCo's
  fullinertia lists M(1,1) M(2,2) M(3,3) M(1,2) M(1,3) M(2,3), the order of URDF's and the
  scene's INERTIA_KEYS, about the centre of mass in the body frame;
- one site per route point, on the body of its link (link 0: the world body), and one spatial
  tendon per spring through its sites in the route's order. The tendon's length is the sum of
  its straight segments, and ``stiffness="k" springlength="L_0"`` gives the energy
  1/2 k (L - L_0)^2 (a single springlength value sets both ends of MuJoCo's dead band to L_0:
  no dead band);
- ``damping`` on each hinge with d_i > 0; a motor (gear 1, no control limits) on each
  actuated joint in the scene's order, so data.ctrl[j] is the torque of the j-th actuated joint
  and zero controls add nothing;
- gravity as given, contacts disabled, the ``energy`` flag on, so that ``mjData.energy`` is
  (V, T) of chaingen.spatial.dynamics: V = -sum m_i g . c_i + sum 1/2 k (L - L_0)^2.

Like the planar codegen.reference.mjcf, this module only writes text (numbers with repr); it
does not import mujoco (codegen.reference.spatial_mujoco runs the model). Nor does it import
chaingen.spatial: tests/test_layout.py does not yet give that package a stage below this one,
and the scene's fields are all it reads.
"""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from .mjcf import (
    MUJOCO_INTEGRATORS,
    MUJOCO_MINIMUM_CAPSULE,
    MUJOCO_MINIMUM_INERTIA,
    body_name,
    joint_name,
    number_text,
    plant_only_comment,
    tendon_xml,
    vector_text,
)


def route_site(spring_index: int, point_index: int) -> str:
    """Name of the site of route point `point_index` of spring `spring_index` (both 0-based)."""
    return f"spring{spring_index}_point{point_index}"


def motor_name(joint: int) -> str:
    """Name of the motor of actuated joint `joint` (1-based)."""
    return f"motor{joint}"


def _check_representable(scene) -> None:
    """Raise ValueError naming the first link MuJoCo's compiler would refuse: a moving body
    needs mass and principal moments of inertia larger than mjMINVAL, and its principal
    moments must satisfy the triangle inequality A + B >= C (true of every rigid body, but a
    scene only promises a positive semi-definite tensor).

    A body on the boundary (a thin plate, A + B = C) passes here: MuJoCo diagonalizes the
    tensor itself and compares its own moments exactly, so whether it takes such a body turns
    on its round-off (spatial_mujoco reports a refusal in one line)."""
    for i, link in enumerate(scene.links):
        if not link.mass > MUJOCO_MINIMUM_INERTIA:
            raise ValueError(
                f"links[{i}].mass: MuJoCo cannot represent link {i + 1} with mass "
                f"{link.mass!r} kg (a moving body needs mass > {MUJOCO_MINIMUM_INERTIA!r} kg)")
        moments = np.linalg.eigvalsh(np.array(link.inertia_matrix(), dtype=float))
        if not moments[0] > MUJOCO_MINIMUM_INERTIA:
            raise ValueError(
                f"links[{i}].inertia: MuJoCo cannot represent link {i + 1} with principal "
                f"moments of inertia {vector_text(*moments)} kg m^2 (a moving body needs each "
                f"> {MUJOCO_MINIMUM_INERTIA!r} kg m^2); give it a positive definite inertia "
                f"to compare with MuJoCo")
        if moments[0] + moments[1] < moments[2] * (1.0 - 1e-12):
            raise ValueError(
                f"links[{i}].inertia: MuJoCo cannot represent link {i + 1} with principal "
                f"moments of inertia {vector_text(*moments)} kg m^2: no rigid body has two "
                f"moments whose sum is below the third (A + B >= C)")


def spatial_mjcf_from_scene(scene, *, dt: float, integrator: str = "RK4",
                            export: bool = False) -> str:
    """MJCF text of the chain of `scene`, a chaingen.spatial.SpatialScene
    (docs/spatial-mujoco.md), time step `dt` (s), MuJoCo `integrator`.

    Bodies, joints and tendons are in the scene's order, so qpos[i-1] is q_i and tendon k is
    scene.springs[k]; nothing is added (no armature, limits, joint stiffness or contacts).

    export (for `chaingen export --mjcf`): also what a user of the file sees: a massless
    capsule (no contacts) from each body's origin to its child's joint origin (the tip link's:
    to its centre of mass), visible sites and tendons, and a keyframe "initial" (key 0)
    holding the scene's initial angles and velocities. The dynamics are the same.

    Raises ValueError for a link MuJoCo cannot represent (see _check_representable), for dt
    that is not positive and finite, and for an unknown integrator.
    """
    if not (dt > 0.0 and dt < float("inf")):
        raise ValueError(f"dt: must be > 0 and finite, got {dt!r}")
    if integrator not in MUJOCO_INTEGRATORS:
        raise ValueError(
            f"integrator: must be one of {', '.join(MUJOCO_INTEGRATORS)}, got {integrator!r}")
    _check_representable(scene)

    # The size of the drawn geometry: 1.5 % of the chain's reach (of its joint offsets).
    reach = sum(float(np.linalg.norm(link.joint.xyz)) for link in scene.links)
    size = 0.015 * (reach if reach > 0.0 else 1.0)
    site_looks = f' size={quoteattr(number_text(size))} rgba="0.2 0.2 0.2 1"' if export else ""

    # Sites per body: index 0 is the world body, index i the body of link i.
    sites: list[list[str]] = [[] for _ in range(scene.n + 1)]
    tendons: list[str] = []
    for k, spring in enumerate(scene.springs):
        for j, point in enumerate(spring.route):
            sites[point.link].append(f"<site name={quoteattr(route_site(k, j))} "
                                     f"pos={quoteattr(vector_text(*point.point))}{site_looks}/>")
        tendons.append(tendon_xml(k, spring.stiffness, spring.rest_length,
                                  [route_site(k, j) for j in range(len(spring.route))],
                                  0.5 * size if export else None))

    # Bodies nest: build from the tip inwards.
    inner = ""
    for i in range(scene.n, 0, -1):
        link = scene.links[i - 1]
        joint = link.joint
        indent = "  " * (i + 1)
        damping = (f" damping={quoteattr(number_text(link.damping))}"
                   if link.damping != 0.0 else "")
        lines = [
            f"{indent}<body name={quoteattr(body_name(i))} "
            f"pos={quoteattr(vector_text(*joint.xyz))} "
            f"euler={quoteattr(vector_text(*joint.rpy))}>",
            f"{indent}  <joint name={quoteattr(joint_name(i))} type=\"hinge\" pos=\"0 0 0\" "
            f"axis={quoteattr(vector_text(*joint.axis))}{damping}/>",
            f"{indent}  <inertial pos={quoteattr(vector_text(*link.com))} "
            f"mass={quoteattr(number_text(link.mass))} "
            f"fullinertia={quoteattr(vector_text(*link.inertia))}/>",
        ]
        if export:
            end = scene.links[i].joint.xyz if i < scene.n else link.com
            # MuJoCo refuses a capsule of zero length, or of one up to 1e-7 m
            if np.linalg.norm(end) > MUJOCO_MINIMUM_CAPSULE:
                lines.append(
                    f"{indent}  <geom name={quoteattr(f'link{i}_geom')} type=\"capsule\" "
                    f"fromto={quoteattr(vector_text(0.0, 0.0, 0.0, *end))} "
                    f"size={quoteattr(number_text(size))} mass=\"0\" contype=\"0\" "
                    f"conaffinity=\"0\" rgba=\"0.5 0.5 0.55 1\"/>")
        lines += [f"{indent}  {site}" for site in sites[i]]
        inner = "\n".join(lines) + "\n" + inner + f"{indent}</body>\n"

    world_sites = "".join(f"    {site}\n" for site in sites[0])
    tendon_block = ("  <tendon>\n" + "\n".join(tendons) + "\n  </tendon>\n") if tendons else ""
    actuator_block = ""
    if scene.actuated:
        motors = "".join(f"    <motor name={quoteattr(motor_name(j))} "
                         f"joint={quoteattr(joint_name(j))} gear=\"1\"/>\n"
                         for j in scene.actuated)
        actuator_block = f"  <actuator>\n{motors}  </actuator>\n"
    keyframe_block = ""
    if export:   # the scene's initial state: mj_resetDataKeyframe(model, data, 0) starts there
        keyframe_block = (
            f"  <keyframe>\n    <key name=\"initial\" "
            f"qpos={quoteattr(vector_text(*scene.initial_angles))} "
            f"qvel={quoteattr(vector_text(*scene.initial_velocities))}/>\n  </keyframe>\n")
    return (
        f"<mujoco model={quoteattr(scene.name)}>\n"
        f"{plant_only_comment(scene, export)}"
        f"  <compiler angle=\"radian\" eulerseq=\"XYZ\"/>\n"
        f"  <option gravity={quoteattr(vector_text(*scene.gravity))} "
        f"integrator={quoteattr(integrator)} timestep={quoteattr(number_text(dt))}>\n"
        f"    <flag contact=\"disable\" energy=\"enable\"/>\n"
        f"  </option>\n"
        f"  <worldbody>\n"
        f"{world_sites}"
        f"{inner}"
        f"  </worldbody>\n"
        f"{tendon_block}"
        f"{actuator_block}"
        f"{keyframe_block}"
        f"</mujoco>\n"
    )
