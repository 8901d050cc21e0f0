"""Study e of issue 33 (docs/studies-spatial-holding.md): the joint torques the 7-joint Panda
needs along a slow motion, with and without a multi-articular spring, and a sweep over the
spring's stiffness and rest length for the least integral of |tau|^2.

    python docs/studies/spatial_holding.py [--figures docs/figures]

The arm is scenes/panda_springs.toml with its multi-articular spring alone (springs[2] of the
file: link 1, a via point on link 3, link 4; it spans joints 2, 3 and 4), the two
mono-articular springs left out. The motion is a quintic in joint space (zero rates and
accelerations at both ends) from the Panda's 'ready' posture to a reach forward with the arm
stretched out (shoulder, joint 2, from -45 to 46 degrees; elbow, joint 4, from -135 to -46),
over T = 9 s. Along it, the torque of joint i is the inverse dynamics

    tau = M(q) qddot + C(q, qdot) qdot + dV_g/dq + dV_s/dq + d qdot,

taken from the generated midpoint solver (its residual at a step whose mid-point is (q, qdot)
and whose rate increment is dt qddot, divided by dt, with zero inputs: exact at any dt, the
residual is the inverse dynamics at the mid-point) with the spring's stiffness and rest length
as run-time parameters; its static part dV/dq from the generated holding_torques. A sweep
over (k, L_0) evaluates the cost J = int_0^T |tau|^2 dt (trapezoid, 901 samples) at every
setting with that one solver. Sweep rows (chaingen sweep) hold summaries of simulations, not
integrals along a prescribed path, so the sweep is this loop over the parameters.

For a fixed path tau = a + k (L - L_0) dL/dq = a + k b - (k L_0) c with b = L dL/dq and
c = dL/dq (numpy, chaingen.spatial.dynamics): J is quadratic in (k, k L_0), and its least
value solves 2 x 2 normal equations; the script checks the sweep against it. A spring whose
length L(t) falls below L_0 pushes: a tendon cannot, so the script reports the best setting
that keeps L >= L_0 all along as well.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from chaingen.simulation import build_solver
from chaingen.spatial import dynamics, load_spatial_scene

DURATION = 9.0                       # s
SAMPLES = 901                        # along the path, every 10 ms
START = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])   # 'ready'
END = np.array([0.0, 0.8, 0.0, -0.8, 0.0, 1.6, np.pi / 4])   # reaching forward, stretched
PARAMETERS = ("springs[0].stiffness", "springs[0].rest_length")
STIFFNESS = np.linspace(0.0, 2500.0, 26)[1:]      # N/m (> 0), every 100 N/m
REST_LENGTH = np.linspace(0.30, 0.80, 26)         # m, every 0.02 m
STEP = 0.01                                       # s, the dt of the inverse-dynamics residual


def arm_scenes():
    """(the Panda with its multi-articular spring alone, the Panda without springs)."""
    panda = load_spatial_scene("panda_springs")
    multi = dataclasses.replace(panda, name="panda_multi", springs=(panda.springs[2],))
    bare = dataclasses.replace(panda, name="panda_bare", springs=())
    return multi, bare


def quintic_path(duration: float = DURATION, samples: int = SAMPLES):
    """(t, q, qdot, qddot) of q(t) = START + (END - START) s(t / T), s = 10 u^3 - 15 u^4 + 6 u^5:
    at rest at both ends."""
    t = np.linspace(0.0, duration, samples)
    u = t / duration
    s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
    ds = (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / duration
    dds = (60 * u - 180 * u ** 2 + 120 * u ** 3) / duration ** 2
    span = END - START
    return t, START + np.outer(s, span), np.outer(ds, span), np.outer(dds, span)


def inverse_dynamics(solver, q, qdot, qddot, parameters=None) -> np.ndarray:
    """tau at every sample from the generated midpoint residual F(dw; x0, u = 0, dt) / dt with
    the mid-point at (q, qdot): w0 = qdot - dw / 2, q0 = q - dt qdot / 2, dw = dt qddot."""
    p = None if parameters is None else solver.parameter_values(parameters)
    torques = np.empty_like(q)
    zero = np.zeros(solver.n)
    for k in range(len(q)):
        dw = STEP * qddot[k]
        x0 = solver.initial_state(q[k] - STEP * qdot[k] / 2, qdot[k] - dw / 2, p)
        torques[k] = solver.residual(dw, x0, zero, STEP, parameters=p) / STEP
    return torques


def holding(solver, q, parameters=None) -> np.ndarray:
    """dV/dq at every sample, from the generated holding_torques."""
    p = None if parameters is None else solver.parameter_values(parameters)
    return np.array([solver.holding_torques(row, p) for row in q])


def cost(t, torques) -> float:
    """J = int |tau|^2 dt (trapezoid), N^2 m^2 s."""
    return float(np.trapezoid((torques ** 2).sum(axis=1), t))


def rms(t, torques) -> float:
    """sqrt(J / (T n)): the root mean square of a joint's torque, N m."""
    return float(np.sqrt(cost(t, torques) / (t[-1] - t[0]) / torques.shape[1]))


def spring_terms(scene, q):
    """(L(t), b = L dL/dq, c = dL/dq) of the scene's one spring along the path (numpy)."""
    unit = dataclasses.replace(scene.springs[0], stiffness=1.0, rest_length=0.0)
    at_zero = dataclasses.replace(scene, springs=(unit,))
    at_one = dataclasses.replace(scene, springs=(dataclasses.replace(unit, rest_length=1.0),))
    b = np.array([dynamics.spring_torques(at_zero, row) for row in q])
    c = b - np.array([dynamics.spring_torques(at_one, row) for row in q])
    lengths = np.array([dynamics.spring_lengths(at_zero, row)[0] for row in q])
    return lengths, b, c


def closed_form(t, a, b, c, min_length: float) -> dict:
    """The least J over (k, L_0) from the normal equations of |a + k b - m c|^2, m = k L_0,
    and the least J with L_0 <= min_length (never compressed) and k >= 0."""
    def inner(x, y):
        return float(np.trapezoid((x * y).sum(axis=1), t))

    gram = np.array([[inner(b, b), -inner(b, c)], [-inner(b, c), inner(c, c)]])
    k, m = np.linalg.solve(gram, [-inner(a, b), inner(a, c)])
    best = {"stiffness": k, "rest_length": m / k, "cost": cost(t, a + k * b - m * c)}
    # On the edge L_0 = min L(t): tau = a + k (b - L_min c), least at k = -<a, e> / <e, e>.
    edge = b - min_length * c
    k_edge = max(0.0, -inner(a, edge) / inner(edge, edge))
    best["tension_only"] = {"stiffness": k_edge, "rest_length": min_length,
                            "cost": cost(t, a + k_edge * edge)}
    return best


def sweep(solver, t, q, qdot, qddot):
    """J at every (k, L_0) of the grid, each from the generated inverse dynamics."""
    grid = np.empty((len(STIFFNESS), len(REST_LENGTH)))
    for i, k in enumerate(STIFFNESS):
        for j, rest in enumerate(REST_LENGTH):
            values = {PARAMETERS[0]: k, PARAMETERS[1]: rest}
            grid[i, j] = cost(t, inverse_dynamics(solver, q, qdot, qddot, values))
    return grid


def run(figures: Path | None = None) -> dict:
    started = time.perf_counter()
    multi, bare = arm_scenes()
    spring = multi.springs[0]
    solver = build_solver(multi, "midpoint", parameters=PARAMETERS, sensitivities=False)
    plain = build_solver(bare, "midpoint", sensitivities=False)
    built = time.perf_counter() - started
    t, q, qdot, qddot = quintic_path()
    without = inverse_dynamics(plain, q, qdot, qddot)
    static = holding(plain, q)
    scene_spring = inverse_dynamics(solver, q, qdot, qddot)
    lengths, b, c = spring_terms(multi, q)
    exact = closed_form(t, without, b, c, float(lengths.min()))
    swept = time.perf_counter()
    grid = sweep(solver, t, q, qdot, qddot)
    swept = time.perf_counter() - swept
    i, j = np.unravel_index(np.argmin(grid), grid.shape)
    tension = REST_LENGTH <= lengths.min()
    tension_grid = np.where(tension[None, :], grid, np.inf)
    ti, tj = np.unravel_index(np.argmin(tension_grid), grid.shape)
    best = {"stiffness": float(STIFFNESS[i]), "rest_length": float(REST_LENGTH[j]),
            "cost": float(grid[i, j])}
    best_values = {PARAMETERS[0]: exact["stiffness"], PARAMETERS[1]: exact["rest_length"]}
    optimum = inverse_dynamics(solver, q, qdot, qddot, best_values)
    results = {
        "built_seconds": built, "sweep_seconds": swept, "settings": grid.size,
        "without": cost(t, without), "without_rms": rms(t, without),
        "inertial_rms": rms(t, without - static), "static_rms": rms(t, static),
        "scene": cost(t, scene_spring), "scene_setting": (spring.stiffness, spring.rest_length),
        "grid_best": best, "exact": exact,
        "grid_tension_best": {"stiffness": float(STIFFNESS[ti]),
                              "rest_length": float(REST_LENGTH[tj]),
                              "cost": float(tension_grid[ti, tj])},
        "optimum_cost": cost(t, optimum), "optimum_rms": rms(t, optimum),
        "length_range": (float(lengths.min()), float(lengths.max())),
        "scene_compressed": bool((lengths < spring.rest_length).any()),
        "optimum_compressed_fraction": float(np.mean(lengths < exact["rest_length"])),
    }
    if figures is not None:
        draw(figures, t, without, scene_spring, optimum, lengths, grid, results)
    return results


def draw(figures: Path, t, without, scene_spring, optimum, lengths, grid, results) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures.mkdir(parents=True, exist_ok=True)
    exact, k0, l0 = results["exact"], *results["scene_setting"]
    fig, axes = plt.subplots(4, 2, figsize=(10, 10), sharex=True)
    for joint, ax in enumerate(axes.flat[:7]):
        ax.plot(t, without[:, joint], label="without the spring")
        ax.plot(t, scene_spring[:, joint], label=f"the scene's spring ({k0:g} N/m, {l0:g} m)")
        ax.plot(t, optimum[:, joint], label=f"least J ({exact['stiffness']:.0f} N/m, "
                                            f"{exact['rest_length']:.3f} m)")
        ax.set_ylabel(f"tau_{joint + 1} (N m)")
        ax.grid(alpha=0.3)
    ax = axes.flat[7]
    ax.plot(t, lengths, color="black", label="spring length L(t)")
    ax.axhline(l0, color="C1", linestyle="--", label="L_0, the scene's")
    ax.axhline(exact["rest_length"], color="C2", linestyle="--", label="L_0, least J")
    ax.set_ylabel("length (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    axes.flat[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    fig.suptitle("Panda along a 9 s quintic path: joint torques with and without the "
                 "multi-articular spring")
    fig.tight_layout()
    fig.savefig(figures / "spatial_holding_torques.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 6))
    relative = grid / results["without"]
    image = ax.pcolormesh(REST_LENGTH, STIFFNESS, relative, shading="nearest", cmap="viridis",
                          vmax=min(2.0, relative.max()))
    lines = ax.contour(REST_LENGTH, STIFFNESS, relative, levels=[0.1, 0.25, 0.5, 1.0],
                       colors="white", linewidths=0.8)
    ax.clabel(lines, fontsize=7, fmt="%g")
    fig.colorbar(image, label="J / J(no spring)")
    ax.axvline(results["length_range"][0], color="red", linestyle="--",
               label="L_0 = min L(t): to its right the spring is compressed somewhere")
    ax.plot(exact["rest_length"], exact["stiffness"], "w*", markersize=14,
            label="least J (closed form)")
    ax.plot(results["grid_best"]["rest_length"], results["grid_best"]["stiffness"], "ro",
            markerfacecolor="none", label="least J on the grid")
    ax.plot(l0, k0, "ws", label="the scene's spring")
    ax.set_xlabel("rest length L_0 (m)")
    ax.set_ylabel("stiffness k (N/m)")
    ax.set_title("J = int |tau|^2 dt over the sweep, relative to the arm without the spring")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(figures / "spatial_holding_sweep.png", dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figures", type=Path, help="write the two figures here")
    results = run(parser.parse_args().figures)
    for key, value in results.items():
        print(f"{key}: {value}")


if __name__ == "__main__":
    main()
