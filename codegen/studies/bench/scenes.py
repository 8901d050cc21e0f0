"""The scaling series' chain: n identical links with a spring on every joint."""
from __future__ import annotations

import math

from ...scene import Scene, parse_scene

SCALING_LINK = {"mass": 1.0, "length": 0.4, "com": 0.2, "fastening": 0.05}
SCALING_MONO_STIFFNESS = 200.0     # N/m: k L r = 4 N m/rad per joint, like m g L
SCALING_MULTI_STIFFNESS = 100.0
#: Rest lengths are this fraction of the straight posture's, so the springs pull from the start.
SCALING_REST_FRACTION = 0.95
#: The chain starts hanging (phi_1 = -pi/2 is straight down), deflected by this at joint 1
#: and bent by SCALING_INITIAL_ANGLE at every other joint. Released from the horizontal instead,
#: a long chain whips: MuJoCo's RK4 at dt = 0.01 s goes unstable from n = 10 on.
SCALING_HANGING_DEFLECTION = 0.2
SCALING_INITIAL_ANGLE = 0.1


def scaling_scene_text(n: int) -> str:
    """TOML of the scaling series' chain of n identical links (see scaling_scene)."""
    link = SCALING_LINK
    inertia = link["mass"] * link["length"] ** 2 / 12
    lines = [f"# chaingen bench scaling series: {n} identical links, a mono-articular spring",
             "# across every joint, multi-articular springs over the first and last joints.",
             f'name = "scaling-{n}"', "gravity = 9.81", "", "[base]",
             f"fastening = {link['fastening']!r}", ""]
    for _ in range(n):
        lines += ["[[links]]", f"mass = {link['mass']!r}", f"inertia = {inertia!r}",
                  f"length = {link['length']!r}", f"com = {link['com']!r}",
                  f"fastening = {link['fastening']!r}", ""]
    # Straight posture, all offsets equal: each segment P_j -> P_{j+1} is one link long.
    for j in range(1, n + 1):
        lines += ["[[springs]]", f"joints = [{j}, {j}]",
                  f"stiffness = {SCALING_MONO_STIFFNESS!r}",
                  f"rest_length = {SCALING_REST_FRACTION * link['length']!r}", ""]
    # Multi-articular springs over the first three joints and, from n = 6 on, over the last
    # three.
    spans = [(1, min(n, 3))] + ([(n - 2, n)] if n >= 6 else [])
    for first, last in spans:
        lines += ["[[springs]]", f"joints = [{first}, {last}]",
                  f"stiffness = {SCALING_MULTI_STIFFNESS!r}",
                  f"rest_length = {SCALING_REST_FRACTION * (last - first + 1) * link['length']!r}",
                  ""]
    angles = ", ".join([repr(-math.pi / 2 + SCALING_HANGING_DEFLECTION)]
                       + [repr(SCALING_INITIAL_ANGLE)] * (n - 1))
    lines += ["[initial]", f"angles = [{angles}]", f"velocities = [{', '.join(['0.0'] * n)}]",
              "", "[simulation]", 'method = "es"', "quadrature = 3", "dt = 0.01",
              "t_end = 10.0", ""]
    return "\n".join(lines)


def scaling_scene(n: int) -> Scene:
    """n identical links (1 kg, 0.4 m, COM at 0.2 m, J = m L^2 / 12, fastenings 0.05 m off the
    axis), g = 9.81, a mono-articular spring across every joint, a multi-articular spring over
    joints 1..min(n, 3) and, for n >= 6, one over joints n-2..n, rest lengths 95 % of the
    straight posture's. At rest, hanging 0.2 rad off the vertical with every other joint bent
    by 0.1 rad. Parsed from TOML like a
    user's file, so it is validated like one."""
    return parse_scene(scaling_scene_text(n), f"<scaling scene n={n}>", f"scaling-{n}")


#: The uneven scaling chain (uneven_scene): link i (from 0) takes entry i mod len of each
#: table, so that neighbours differ and the pattern repeats only every 60 links.
UNEVEN_MASSES = (1.0, 1.6, 0.7, 1.3, 0.5)                  # kg
UNEVEN_LENGTHS = (0.4, 0.3, 0.5, 0.35)                      # m
UNEVEN_COM_FRACTIONS = (0.5, 0.35, 0.65)                    # a_i / L_i
UNEVEN_COM_NORMALS = (0.03, -0.02, 0.05, -0.04, 0.01)       # b_i (m): every COM off the axis
UNEVEN_INERTIA_FACTORS = (1.0, 1.8, 0.6)                    # J_i / (m_i L_i^2 / 12)
UNEVEN_FASTENINGS = (0.05, 0.04, 0.06, 0.045)              # r_{i+1} (m); the base's is 0.05
UNEVEN_PATTERN = (UNEVEN_MASSES, UNEVEN_LENGTHS, UNEVEN_COM_FRACTIONS, UNEVEN_COM_NORMALS,
                  UNEVEN_INERTIA_FACTORS, UNEVEN_FASTENINGS)


def _uneven_links(n: int) -> list[dict]:
    links = []
    for i in range(n):
        mass, length, fraction, normal, factor, fastening = (table[i % len(table)]
                                                              for table in UNEVEN_PATTERN)
        links.append({"mass": mass, "length": length, "com": fraction * length,
                      "com_normal": normal, "inertia": factor * mass * length ** 2 / 12,
                      "fastening": fastening})
    return links


def uneven_scene_text(n: int) -> str:
    """TOML of the uneven scaling chain of n links (see uneven_scene)."""
    links = _uneven_links(n)
    base = SCALING_LINK["fastening"]
    offsets = [base] + [link["fastening"] for link in links]   # r_1 .. r_{n+1}
    # Straight posture: the segment P_j -> P_{j+1} runs L_j along and r_{j+1} - r_j across.
    segments = [math.hypot(links[j]["length"], offsets[j + 1] - offsets[j]) for j in range(n)]
    lines = [f"# chaingen bench uneven scaling series: {n} links of uneven mass, length and",
             "# inertia with their centres of mass off the link axis, a mono-articular spring",
             "# across every joint, multi-articular springs over the first and last joints.",
             f'name = "uneven-{n}"', "gravity = 9.81", "", "[base]",
             f"fastening = {base!r}", ""]
    for link in links:
        lines += ["[[links]]"] + [f"{key} = {link[key]!r}" for key in
                                  ("mass", "inertia", "length", "com", "com_normal",
                                   "fastening")] + [""]
    for j in range(1, n + 1):
        lines += ["[[springs]]", f"joints = [{j}, {j}]",
                  f"stiffness = {SCALING_MONO_STIFFNESS!r}",
                  f"rest_length = {SCALING_REST_FRACTION * segments[j - 1]!r}", ""]
    spans = [(1, min(n, 3))] + ([(n - 2, n)] if n >= 6 else [])
    for first, last in spans:
        straight = sum(segments[first - 1:last])
        lines += ["[[springs]]", f"joints = [{first}, {last}]",
                  f"stiffness = {SCALING_MULTI_STIFFNESS!r}",
                  f"rest_length = {SCALING_REST_FRACTION * straight!r}", ""]
    angles = ", ".join([repr(-math.pi / 2 + SCALING_HANGING_DEFLECTION)]
                       + [repr(SCALING_INITIAL_ANGLE)] * (n - 1))
    lines += ["[initial]", f"angles = [{angles}]", f"velocities = [{', '.join(['0.0'] * n)}]",
              "", "[simulation]", 'method = "es"', "quadrature = 3", "dt = 0.01",
              "t_end = 10.0", ""]
    return "\n".join(lines)


def uneven_scene(n: int) -> Scene:
    """The scaling chain's uneven sibling: n links whose mass, length, COM along the link,
    COM normal to it (every one off the axis, b_i != 0), inertia and fastening follow the
    fixed cyclic tables UNEVEN_* (periods 5, 4, 3, 5, 3, 4), g = 9.81, the same springs as
    scaling_scene (stiffnesses, spans, rest lengths 95 % of the straight posture's) and the
    same initial state. Parsed from TOML like a user's file."""
    return parse_scene(uneven_scene_text(n), f"<uneven scene n={n}>", f"uneven-{n}")


#: The scaling series' chains by name (config.SCALING_SERIES).
SCALING_CHAINS = {"identical": scaling_scene, "uneven": uneven_scene}
