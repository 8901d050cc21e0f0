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


def test_the_balance_errors_against_k_are_what_the_runs_give():
    """The table: 10 s of four_link_actuated's free fall (no torques, the scene's dt) with es
    and K = 1, 3, 5, 7. K = 1 and 3 are quadrature errors (to the doc's two digits); from
    K = 5 on the error is the round-off of the sums, which moves from one version of the code
    to the next: the doc's figures are within ten times the run's, and below 1e-13 of H."""
    import chaingen

    row = re.search(r"^  \| balance error \(J\) \|(.*)\|$", DOC.read_text(), re.M)
    quoted = dict(zip((1, 3, 5, 7), (float(cell) for cell in row.group(1).split("|"))))
    scene = chaingen.load_reference_scene("four_link_actuated")
    dt = scene.simulation.dt
    for quadrature, figure in quoted.items():
        solver = chaingen.build_solver(scene, "es", quadrature, sensitivities=False)
        result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                 n_steps=round(10.0 / dt))
        error = float(np.abs(result.balance_error).max())
        if quadrature <= 3:
            assert f"{figure:.1e}" == f"{error:.1e}", (quadrature, error)
        else:
            assert error / 10 <= figure <= error * 10, (quadrature, error)
            assert error < 1e-13 * abs(result.energy[0]), (quadrature, error)
