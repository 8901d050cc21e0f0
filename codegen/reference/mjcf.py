"""MJCF (MuJoCo XML) of a scene's chain: the independent reference model of model.md section 10.

MuJoCo represents the chain of model.md sections 1-3 exactly:

- body i carries link i, with a hinge about z at its origin (joint i); body 1 sits at the world
  origin, body i at (L_{i-1}, 0, 0) in body i-1, so qpos are the relative angles phi_i;
- ``<inertial pos="a_i b_i 0" mass="m_i" diaginertia="J_i J_i J_i"/>``: the COM
  c_i = (a_i, b_i) in the link frame and J_i about it (only the z entry acts on a planar chain);
- one site per fastening: P_1 on the world body at (0, r_1, 0), P_{i+1} on body i at
  (L_i, r_{i+1}, 0); a spring that overrides the offsets gets its own sites;
- one spatial tendon per spring through the sites P_first .. P_{last+1}. Its length is the sum
  of the segment lengths s_j, and ``stiffness="k" springlength="S_0"`` gives the energy
  1/2 k (sum_j s_j - S_0)^2 of model.md section 2 (a single springlength value sets both ends
  of MuJoCo's dead band to S_0, i.e. no dead band);
- gravity (0, -g, 0), contacts disabled, the ``energy`` flag on, so that ``mjData.energy`` is
  (V, T) of model.md section 3.

This module only writes text; it does not import mujoco (see codegen.mujoco_reference).
"""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

from ..scene import Scene

# MuJoCo's mjMINVAL: the compiler rejects a moving body whose mass or principal inertia is not
# larger than this ("mass and inertia of moving bodies must be larger than mjMINVAL").
MUJOCO_MINIMUM_INERTIA = 1e-15

# MuJoCo's compiler refuses a capsule whose fromto ends are this close or closer ("fromto
# points too close in geom"; measured with MuJoCo 4.0.1: 1e-7 m refused, 1.0000000000021e-7 m
# taken). The export leaves out a shorter link's capsule, which only draws it (no mass, no
# contacts), as the spatial export leaves out one of zero length.
MUJOCO_MINIMUM_CAPSULE = 1e-7

# The values of <option integrator=...> that MuJoCo 4 accepts (it rejects e.g. "rk4").
MUJOCO_INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")


def number_text(x: float) -> str:
    """A float as the shortest text that round-trips (repr), never rounded."""
    return repr(float(x))


def vector_text(*xs: float) -> str:
    return " ".join(number_text(x) for x in xs)


def chain_fastening_site(j: int) -> str:
    """Name of the site of chain fastening P_j (1-based), shared by springs without offsets."""
    return f"fastening{j}"


def spring_fastening_site(spring_index: int, j: int) -> str:
    """Name of the site of fastening P_j of spring `spring_index` (0-based) with own offsets."""
    return f"spring{spring_index}_fastening{j}"


def tendon_name(spring_index: int) -> str:
    """Name of the tendon of spring `spring_index` (0-based, the scene's order)."""
    return f"spring{spring_index}"


def tendon_xml(k: int, stiffness: float, rest_length: float, sites, width: float | None) -> str:
    """Spring k's spatial tendon through the named sites: energy 1/2 k (L - S_0)^2 (a single
    springlength, no dead band); drawn `width` wide in an exported model, else not drawn."""
    path = "".join(f"\n      <site site={quoteattr(name)}/>" for name in sites)
    drawn = (f' width={quoteattr(number_text(width))} rgba="0.7 0.1 0.1 1"'
             if width is not None else "")
    return (f"    <spatial name={quoteattr(tendon_name(k))} "
            f"stiffness={quoteattr(number_text(stiffness))} "
            f"springlength={quoteattr(number_text(rest_length))}{drawn}>"
            f"{path}\n    </spatial>")


def plant_only_comment(scene, export: bool) -> str:
    """The comment an exported model of a controlled scene (a [control] table) opens with: MJCF
    has no counterpart of the law, so the file is the plant alone; empty otherwise."""
    control = getattr(scene, "control", None)
    if not export or control is None:
        return ""
    return ("  <!-- The plant only, no controller: the scene's [control] law (law = "
            f"{quoteattr(control.law)}: energy shaping to its target with damping injection, "
            "docs/controllers.md) is not in this model. Its motors are the inputs: drive "
            "data.ctrl with the law yourself. -->\n")


def body_name(i: int) -> str:
    """Name of the body of link i (1-based)."""
    return f"link{i}"


def joint_name(i: int) -> str:
    """Name of the hinge of joint i (1-based)."""
    return f"joint{i}"


def mjcf_from_scene(scene: Scene, *, dt: float, integrator: str = "RK4",
                    export: bool = False) -> str:
    """MJCF text of `scene`'s chain (model.md section 10), time step `dt`, MuJoCo `integrator`.

    Bodies, joints and tendons are in the scene's order, so qpos[i-1] is phi_i and tendon k is
    scene.springs[k]. Joint damping d_i becomes the hinge's ``damping``; nothing else (no
    armature, limits or joint stiffness) is added.

    export (`chaingen export --mjcf`): also what a user of the file sees and drives: a capsule
    geom along each link longer than MUJOCO_MINIMUM_CAPSULE (no contacts, no mass: the
    <inertial> stays the only mass), visible sites and tendons, and a motor (gear 1, no
    control limits) on each actuated joint, in the scene's order, so that data.ctrl[j] is
    the torque of the j-th actuated joint, and a keyframe "initial" (key 0) holding the
    scene's initial angles and velocities as qpos and qvel. The dynamics are those of the
    reference model.

    Raises ValueError for a link with J_i = 0 (MuJoCo cannot represent a moving body without
    rotational inertia), for dt that is not positive and finite, and for an unknown integrator.
    """
    if not (dt > 0.0 and dt < float("inf")):
        raise ValueError(f"dt: must be > 0 and finite, got {dt!r}")
    if integrator not in MUJOCO_INTEGRATORS:
        raise ValueError(
            f"integrator: must be one of {', '.join(MUJOCO_INTEGRATORS)}, got {integrator!r}")
    for i, link in enumerate(scene.links, start=1):
        if not link.inertia > MUJOCO_MINIMUM_INERTIA:
            raise ValueError(
                f"links[{i - 1}].inertia: MuJoCo cannot represent a link with inertia "
                f"{link.inertia!r} (a moving body needs inertia > {MUJOCO_MINIMUM_INERTIA!r} "
                f"kg m^2); give link {i} a positive moment of inertia to compare with MuJoCo")

    # Sites per body: index 0 is the world body, index i the body of link i. The fastening
    # P_j lies on body j-1 at (L_{j-1}, r_j, 0) (at (0, r_1, 0) on the world body).
    sites: list[list[str]] = [[] for _ in range(scene.n + 1)]
    size = 0.015 * sum(link.length for link in scene.links)      # of the drawn geometry
    looks = (f' size={quoteattr(number_text(size))} rgba="0.2 0.2 0.2 1"' if export else "")

    def site_xml(name: str, j: int, r: float) -> str:
        x = 0.0 if j == 1 else scene.links[j - 2].length
        return f"<site name={quoteattr(name)} pos={quoteattr(vector_text(x, r, 0.0))}{looks}/>"

    for j, r in enumerate(scene.chain_fastenings(), start=1):
        sites[j - 1].append(site_xml(chain_fastening_site(j), j, r))

    tendons: list[str] = []
    for k, spring in enumerate(scene.springs):
        fastenings = range(spring.first, spring.last + 2)
        if spring.offsets is None:
            names = [chain_fastening_site(j) for j in fastenings]
        else:
            names = [spring_fastening_site(k, j) for j in fastenings]
            for j, r in zip(fastenings, scene.spring_fastenings(spring)):
                sites[j - 1].append(site_xml(spring_fastening_site(k, j), j, r))
        tendons.append(tendon_xml(k, spring.stiffness, spring.rest_length, names,
                                  0.5 * size if export else None))

    # Bodies nest: build from the tip inwards.
    inner = ""
    for i in range(scene.n, 0, -1):
        link = scene.links[i - 1]
        indent = "  " * (i + 1)
        x = 0.0 if i == 1 else scene.links[i - 2].length
        damping = (f" damping={quoteattr(number_text(link.damping))}"
                   if link.damping != 0.0 else "")
        lines = [
            f"{indent}<body name={quoteattr(body_name(i))} "
            f"pos={quoteattr(vector_text(x, 0.0, 0.0))}>",
            f"{indent}  <joint name={quoteattr(joint_name(i))} type=\"hinge\" "
            f"pos=\"0 0 0\" axis=\"0 0 1\"{damping}/>",
            f"{indent}  <inertial pos={quoteattr(vector_text(link.com, link.com_normal, 0.0))} "
            f"mass={quoteattr(number_text(link.mass))} "
            f"diaginertia={quoteattr(vector_text(link.inertia, link.inertia, link.inertia))}/>",
        ]
        if export and link.length > MUJOCO_MINIMUM_CAPSULE:
            lines.append(
                f"{indent}  <geom name={quoteattr(f'link{i}_geom')} type=\"capsule\" "
                f"fromto={quoteattr(vector_text(0.0, 0.0, 0.0, link.length, 0.0, 0.0))} "
                f"size={quoteattr(number_text(size))} mass=\"0\" contype=\"0\" "
                f"conaffinity=\"0\" rgba=\"0.5 0.5 0.55 1\"/>")
        lines += [f"{indent}  {site}" for site in sites[i]]
        body = "\n".join(lines) + "\n"
        body += inner
        body += f"{indent}</body>\n"
        inner = body

    world_sites = "".join(f"    {site}\n" for site in sites[0])
    tendon_block = ("  <tendon>\n" + "\n".join(tendons) + "\n  </tendon>\n") if tendons else ""
    actuator_block = ""
    if export and scene.actuated_joints:
        motors = "".join(f"    <motor name={quoteattr(f'motor{j}')} "
                         f"joint={quoteattr(joint_name(j))} gear=\"1\"/>\n"
                         for j in scene.actuated_joints)
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
        f"  <compiler angle=\"radian\"/>\n"
        f"  <option gravity={quoteattr(vector_text(0.0, -scene.gravity, 0.0))} "
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
