"""docs/choosing.md (when to pick order 2, 4 or 6, es's K at order 6, adaptive steps) and the
README's and controllers.md's option and size statements, against the program: the defaults
and stage counts the page names are the program's, its tables are those its script writes
(docs/studies/choosing.py, every run it makes), the summary's ratios are read from its table,
the energy errors of es at order 6 come from a run, and the sizes of the five-link vi package
from generating it. Times are not checked (they are the machine's)."""
from __future__ import annotations

import importlib.util
import json
import re

import numpy as np
import pytest

import chaingen
from chaingen.runtime import contract
from chaingen.scene.values import Simulation
from chaingen.symbolic.composition import (
    COMPOSITIONS,
    FROM_ORDER_4,
    GALERKIN_MIN_QUADRATURE,
)

from helpers import ROOT

DOC = ROOT / "docs" / "choosing.md"


def text(path=DOC) -> str:
    """The document with its line breaks as spaces (sentences wrap anywhere)."""
    return " ".join(path.read_text().split())


def script():
    spec = importlib.util.spec_from_file_location("choosing", ROOT / "docs/studies/choosing.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def tables() -> tuple[dict, dict]:
    """The fixed-step rows {(scheme, order, dt): cells} and adaptive {(order, tol): cells}."""
    fixed, adaptive = {}, {}
    for line in DOC.read_text().splitlines():
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        if len(cells) == 8 and re.fullmatch(r"(es K=\d|vi|midpoint)", cells[0]):
            fixed[cells[0], int(cells[1]), float(cells[2])] = cells[3:]
        elif len(cells) == 8 and re.fullmatch(r"\d", cells[0]) and "e-" in cells[1]:
            adaptive[int(cells[0]), float(cells[1])] = cells[2:]
    return fixed, adaptive


def prose(cell: str) -> str:
    """A table's 3.5e-08 as the text writes it: 3.5e-8."""
    return re.sub(r"e([-+])0(\d)", r"e\1\2", cell)


def test_the_defaults_and_stages_it_names_are_the_programs():
    doc = text()
    assert Simulation().order == 2 and "(scene key `simulation.order`, default 2)" in doc
    assert (Simulation().rtol, Simulation().atol) == (0.0, 0.0)
    assert "(default 0 and 0: fixed steps)" in doc
    assert len(COMPOSITIONS[4]) == 5 and "**Order 4** (5 stages)" in doc
    assert len(COMPOSITIONS[6]) == 9 and "`vi` and `midpoint` compose 9 stages" in doc
    assert len(FROM_ORDER_4) == 5 and "`es` composes 5 stages of its Galerkin step" in doc
    assert GALERKIN_MIN_QUADRATURE == 2 and "Gauss-Lobatto rule** of K + 1 nodes (K >= 2)" in doc
    assert chaingen.load_reference_scene("three_link_mono").simulation.quadrature == 3
    assert "three_link_mono (its scene's K = 3" in doc
    defaults = {method: json.loads((ROOT / "generated" / f"three_link_mono_{method}" /
                                    "chaingen.json").read_text())["newton_defaults"]
                for method in ("es", "vi", "midpoint")}
    assert {d["update_rtol"] for d in defaults.values()} == {1e-10}
    assert "(`update_rtol` 1e-10, and simplified Newton kept across steps)" in doc
    assert defaults["vi"]["reuse_jacobian"] == contract.JACOBIAN_ACROSS_STEPS
    assert defaults["midpoint"]["reuse_jacobian"] == contract.JACOBIAN_PER_STEP
    assert defaults["es"]["reuse_jacobian"] == contract.JACOBIAN_CHORD_ACROSS_STEPS
    assert "`es` and `midpoint` solve each step with Newton-chord" in doc


def test_its_tables_hold_every_run_of_its_script():
    study = script()
    fixed, adaptive = tables()
    expected = {(method + (f" K={quadrature}" if quadrature else ""), order, dt)
                for method, quadrature, order in study.FIXED for dt in study.DTS}
    assert set(fixed) == expected
    assert set(adaptive) == {(order, tolerance) for order in (2, 4)
                             for tolerance in study.TOLERANCES}
    assert study.SAMPLE_INTERVAL == 0.1 and "samples every 0.1 s (`dt = 0.1`" in text()
    assert study.SCENE == "three_link_mono" and study.T_END == 10.0


def test_its_summary_is_read_from_its_table():
    """The ratios and numbers of 'In short' and 'Read from it' are those of the table."""
    fixed, _ = tables()
    doc = text()

    def per_step(scheme, order, dt=0.01):
        return float(fixed[scheme, order, dt][0])

    def ratio(scheme, order, base=None):
        return per_step(scheme, order) / per_step(base or scheme, 2)

    order_4 = [ratio("es K=3", 4), ratio("vi", 4), ratio("midpoint", 4)]
    assert f"costs {min(order_4):.1f} to {max(order_4):.1f} times an order-2 step" in doc
    assert f"({ratio('vi', 6):.1f} and {ratio('midpoint', 6):.1f} times an order-2 step)" in doc
    es_6 = [ratio(f"es K={k}", 6, "es K=3") for k in (2, 3, 5)]
    assert f"{es_6[0]:.0f} to {es_6[2]:.0f} times its order-2 step" in doc
    assert f"`es` {ratio('es K=3', 4):.1f} times at order 4, and {es_6[0]:.0f}, " \
           f"{es_6[1]:.0f} and {es_6[2]:.0f} times at order 6" in doc
    assert f"K = 5 costs {per_step('es K=5', 6) / per_step('es K=3', 6):.1f} times K = 3" in doc
    energy = {k: prose(fixed[f"es K={k}", 6, 0.1][4]) for k in (2, 3, 5)}
    assert (f"{energy[2]} J with K = 2, {energy[3]} J with K = 3 and {energy[5]} J "
            f"with K = 5") in doc
    assert "keeps its energy to round-off with every K" in doc
    assert max(float(fixed[f"es K={k}", 6, dt][4]) for k in (2, 3, 5) for dt in (0.1, 0.05, 0.01)
               ) <= 2.5e-13
    orders_2 = [per_step(scheme, 2) for scheme in ("es K=3", "vi", "midpoint")]
    assert f"cheapest step: {min(orders_2):.1f} to {max(orders_2):.1f} us" in doc
    # CPU per simulated second: the step's time over dt
    for scheme, order, dt, said in [
            ("midpoint", 2, 0.01, "`midpoint` {} us at order 2 (dt = 0.01 s)"),
            ("midpoint", 4, 0.1, "and {} us at order 4 (dt = 0.1 s"),
            ("vi", 6, 0.1, "`vi` order 6 at dt = 0.1 s {} us"),
            ("es K=2", 6, 0.1, "`es` order 6 (K = 2) at dt = 0.1 s {} us")]:
        assert said.format(round(per_step(scheme, order, dt) / dt)) in doc
    assert max(float(row[4]) for (scheme, _, dt), row in fixed.items()
               if scheme.startswith("es") and dt == 0.01) <= 2.5e-13
    # adaptive against fixed steps
    _, adaptive = tables()
    cpu, _, _, _, at_3, _ = adaptive[2, 1e-8]
    fixed_cpu = per_step("es K=3", 4, 0.1) * 100 / 1000
    assert (f"rtol = atol = 1e-8 spent {cpu[:-1]} ms on 10 s for {prose(at_3)} rad at t = 3 s; "
            f"fixed order 4 at dt = 0.1 s spent {fixed_cpu:.2f} ms for "
            f"{prose(fixed['es K=3', 4, 0.1][3])} rad") in doc
    fixed_005 = per_step("es K=3", 4, 0.05) * 200 / 1000
    assert adaptive[4, 1e-6][1] == "200 (0)" and adaptive[4, 1e-6][3:5] == \
        fixed["es K=3", 4, 0.05][2:4]
    assert (f"costs {float(adaptive[4, 1e-6][0]) / fixed_005:.1f} times its {fixed_005:.2f} ms"
            in doc)
    order_2 = max(float(row[5]) for (order, _), row in adaptive.items() if order == 2)
    assert (f"(at most {prose(f'{order_2:.1e}')} J in the adaptive runs here at order 2; "
            f"{prose(adaptive[4, 1e-6][5])} J at order 4 and 1e-6, whose steps were all 0.05 s)"
            in doc)
    assert adaptive[4, 1e-6][2] == "5.0e-02, 5.0e-02"


def test_the_readme_names_every_newton_option():
    """Every Newton option of the contract is a documented flag; --energy-tol's default too."""
    readme = text(ROOT / "README.md")
    for field in contract.NEWTON_OPTIONS:
        assert f"`--{field.name.replace('_', '-')} " in readme, field.name
    energy_tol = {field.name: field for field in contract.NEWTON_OPTIONS}["energy_tol"]
    assert energy_tol.default == 0.01
    assert "is refused and split (default 0.01, 0 for no check;" in readme


@pytest.mark.compile
def test_es_order_6_energy_is_a_runs_and_round_off():
    """The energy errors of es at order 6 in the table (dt = 0.1 s over 10 s, K = 2 and 3)
    are those of a run, to the two digits printed, and round-off of the energy with either
    rule (the step corrects its rule's error on the energy)."""
    fixed, _ = tables()
    scene = chaingen.load_reference_scene("three_link_mono")
    for quadrature in (2, 3):
        solver = chaingen.build_solver(scene, "es", quadrature, order=6, sensitivities=False)
        run = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.1,
                              n_steps=100)
        energy = run.column("energy")
        measured = np.abs(energy - energy[0]).max()
        assert f"{measured:.1e}" == fixed[f"es K={quadrature}", 6, 0.1][4]
        assert measured <= 1e-12 * np.abs(energy).max()
        assert f"{run.newton_iterations / 100:.2f}" == fixed[f"es K={quadrature}", 6, 0.1][1]


@pytest.mark.heavy
def test_the_sensitivities_share_of_the_five_link_vi_package():
    """README and controllers.md give the model code's size of vi on the five-link test scene
    with and without step_sensitivities: generated here."""
    from chaingen.generate.package import generate_package, model_c_bytes
    from chaingen.scene import load_scene

    scene = load_scene(ROOT / "tests" / "scenes" / "five_link_biarticular.toml")
    sizes = []
    for sensitivities in (True, False):
        package = generate_package(scene, "vi", 1, sensitivities=sensitivities)
        sizes.append(round(model_c_bytes(package) / 1000))
    with_them, without = sizes
    assert f"for `vi` at n = 5: {with_them} kB of model code with them, {without} kB without" \
        in text(ROOT / "README.md")
    assert f"is {with_them} kB with them and {without} kB without" \
        in text(ROOT / "docs" / "controllers.md")
