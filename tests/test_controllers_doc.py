"""docs/controllers.md from runs: its Python example runs as written and holds its target, and
its table of balance errors against K is what the runs give."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.compile

DOC = Path(__file__).resolve().parent.parent / "docs" / "controllers.md"


def python_block() -> str:
    section = DOC.read_text().split("## Closing the loop in Python", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_python_loop_example_holds_its_target(capsys):
    pytest.importorskip("scipy")
    namespace: dict = {}
    exec(compile(python_block(), str(DOC), "exec"), namespace)
    assert namespace["pd_error"] < 1e-3          # the PD reaches the raised posture
    assert namespace["lqr_error"] < 1e-6         # the LQR reaches it more closely still
    printed = capsys.readouterr().out
    # the document quotes what the block prints
    assert printed.strip() in DOC.read_text().replace("`", "")


@pytest.mark.slow
def test_the_balance_errors_against_k_are_what_the_runs_give():
    """The table: 10 s of four_link_actuated's free fall (no torques, the scene's dt) with es
    and K = 1, 3, 5, 7, with the default exact gradient and with the quadrature alone. K = 1
    and 3 of the quadrature alone are quadrature errors (to the doc's two digits); every other
    figure is the round-off of the sums, which moves from one version of the code to the next:
    the doc's figures are within ten times the run's, and below 1e-13 of H."""
    import chaingen

    text = DOC.read_text()
    scene = chaingen.load_reference_scene("four_link_actuated")
    dt = scene.simulation.dt
    for label, gradient in (("balance error (J)", "exact"), ("quadrature alone (J)", "quadrature")):
        row = re.search(rf"^  \| {re.escape(label)} \|(.*)\|$", text, re.M)
        quoted = dict(zip((1, 3, 5, 7), (float(cell) for cell in row.group(1).split("|"))))
        for quadrature, figure in quoted.items():
            solver = chaingen.build_solver(scene, "es", quadrature, sensitivities=False,
                                           gradient=gradient)
            result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                     n_steps=round(10.0 / dt))
            error = float(np.abs(result.balance_error).max())
            if gradient == "quadrature" and quadrature <= 3:
                assert f"{figure:.1e}" == f"{error:.1e}", (quadrature, error)
            else:
                assert error / 10 <= figure <= error * 10, (gradient, quadrature, error)
                assert error <= 1e-13 * np.abs(result.energy).max(), (gradient, quadrature)
