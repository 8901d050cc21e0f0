"""es's energy with the exact discrete gradient (the default) and with the quadrature alone,
on the scenes of issue 32 (docs/model.md section 4): python docs/studies/exact_gradient.py.
Prints two tables: the largest |H - H0| (or, with torques or damping, the balance error)
relative to max |H| of the run; and the angles' error at t = 1 s against DOP853 at
rtol = atol = 1e-13 (K = 3, both gradients). --order6: the order-6 energy rows alone."""
import dataclasses
import sys
import time

import numpy as np

from chaingen.reference.scipy_peer import simulate_scipy
from chaingen.scene import load_reference_scene
from chaingen.simulation import build_solver
from chaingen.studies.bench.scaling import scaling_scene


def stiff_chain(n: int, mono: float, multi: float):
    """The scaling chain of n links with stiff springs: `mono` N/m across every joint,
    `multi` on the multi-articular springs."""
    scene = scaling_scene(n)
    springs = tuple(dataclasses.replace(s, stiffness=mono if s.first == s.last else multi)
                    for s in scene.springs)
    return dataclasses.replace(scene, springs=springs, name=f"stiff-{n}")


def energy_row(label, scene, gradient, *, dt, t_end, order=2, quadrature=3):
    started = time.perf_counter()
    solver = build_solver(scene, "es", quadrature, sensitivities=False, order=order,
                          gradient=gradient)
    steps = round(t_end / dt)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                             n_steps=steps, every=max(1, steps // 2000))
    error = result.balance_error if result.has_flows else result.energy_error
    relative = np.abs(error).max() / np.abs(result.energy).max()
    print(f"| {label} | {order} | {gradient} | {dt:g} | {t_end:g} | {relative:.1e} | "
          f"{result.mean_newton_iterations:.2f} | {time.perf_counter() - started:.0f} |",
          flush=True)


def trajectory_row(name, gradient, dt):
    scene = load_reference_scene(name)
    reference = simulate_scipy(scene, "DOP853", 1e-13, 1e-13, 1.0, [1.0])
    solver = build_solver(scene, "es", 3, sensitivities=False, gradient=gradient)
    steps = round(1.0 / dt)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                             n_steps=steps, every=steps)
    error = np.abs(np.angle(np.exp(1j * (result.phi[-1] - reference.final_angles)))).max()
    print(f"| {name} | {gradient} | {dt:g} | {error:.4e} |", flush=True)


def order6_rows():
    """The order-6 rows alone (docs/model.md sections 4.3 and 16): --order6."""
    for name in ("three_link_mono", "three_link_multi", "four_link_actuated"):
        energy_row(name, load_reference_scene(name), "exact", dt=0.01, t_end=10.0, order=6)


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    print("| scene | order | gradient | dt (s) | t_end (s) | max energy error / max H | "
          "Newton per step | wall s |\n|---|---|---|---|---|---|---|---|")
    if "--order6" in sys.argv:
        order6_rows()
        sys.exit()
    for gradient in ("exact", "quadrature"):
        energy_row("scaling chain, 20 links", scaling_scene(20), gradient, dt=0.01,
                   t_end=20.0 if quick else 200.0)
        energy_row("10 links, springs 2e5 / 3.5e5 N/m", stiff_chain(10, 2e5, 3.5e5), gradient,
                   dt=1e-3, t_end=2.0)
    for name in ("three_link_mono", "three_link_multi", "four_link_actuated"):
        for order in (4, 6):
            energy_row(name, load_reference_scene(name), "exact", dt=0.01, t_end=10.0,
                       order=order)
    print("\n| scene | gradient | dt (s) | max angle error at t = 1 s (rad) |\n|---|---|---|---|")
    for name in ("three_link_mono", "three_link_multi", "four_link_actuated"):
        for dt in (0.01, 0.05):
            for gradient in ("exact", "quadrature"):
                trajectory_row(name, gradient, dt)
