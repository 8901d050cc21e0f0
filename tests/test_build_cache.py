"""build_solver's lookup by inputs (codegen/generate/key.py, runtime/build.py's index): an
unchanged solver loads from the cache without SymPy or CasADi, equal to the one first built; a
broken or stale entry falls back to generating and is repaired; other inputs miss it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from chaingen.generate.key import solver_key
from chaingen.runtime.build import DEFAULT_OPTIMISATION, INDEX, cache_directory, compiler

pytestmark = pytest.mark.compile

#: A child process: build_solver of a reference scene, a short run, and what it imported.
CHILD = """
import json, sys, time
started = time.perf_counter()
import chaingen
scene = chaingen.load_reference_scene(sys.argv[1])
solver = chaingen.build_solver(scene, sys.argv[2], 3, sensitivities=False)
built = time.perf_counter() - started
result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=200)
print(json.dumps({"seconds": built, "sympy": "sympy" in sys.modules,
                  "casadi": "casadi" in sys.modules, "phi": result.phi[-1].tolist(),
                  "studies": "chaingen.studies.sweep" in sys.modules}))
"""


def child(scene: str, method: str, cache) -> dict:
    result = subprocess.run([sys.executable, "-c", CHILD, scene, method], capture_output=True,
                            text=True, env={**os.environ,
                                            "CHAINGEN_CACHE_DIR": str(cache)})
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def key(scene_name: str, method: str, **options) -> str:
    from chaingen import load_reference_scene

    return solver_key(load_reference_scene(scene_name), method, 3,
                      sensitivities=options.get("sensitivities", False),
                      parameters=options.get("parameters", ()), order=options.get("order", 2),
                      build=(compiler(), *DEFAULT_OPTIMISATION))


def test_second_build_loads_without_sympy_or_casadi(tmp_path):
    first = child("three_link_mono", "vi", tmp_path)
    assert first["sympy"] and first["casadi"]            # generated the first time
    second = child("three_link_mono", "vi", tmp_path)
    assert not second["sympy"] and not second["casadi"]  # loaded from the index
    assert not second["studies"]                        # chaingen.sweep loads on first use
    assert second["phi"] == first["phi"]                 # the same solver, bit for bit
    print(f"build_solver in a new process: {first['seconds']:.2f} s, then "
          f"{second['seconds']:.3f} s from the index")


@pytest.mark.parametrize("damage", ["corrupt", "library gone", "wrong library"])
def test_broken_entry_falls_back_and_is_repaired(tmp_path, damage):
    first = child("three_link_gravity", "midpoint", tmp_path)
    entry = tmp_path / INDEX / f"{key('three_link_gravity', 'midpoint')}.json"
    assert entry.is_file()
    record = json.loads(entry.read_text())
    if damage == "corrupt":
        entry.write_text(entry.read_text()[:40])
    elif damage == "library gone":
        (tmp_path / record["library"]).unlink()
    else:
        record["build_hash"] = "0" * 20
        entry.write_text(json.dumps(record))
    again = child("three_link_gravity", "midpoint", tmp_path)
    assert again["sympy"]                                 # generated again ...
    assert again["phi"] == first["phi"]
    assert json.loads(entry.read_text())["build_hash"] == record["build_hash"] or \
        damage == "wrong library"
    assert not child("three_link_gravity", "midpoint", tmp_path)["sympy"]   # ... and repaired


def test_other_inputs_have_other_keys():
    base = key("three_link_mono", "es")
    assert base == key("three_link_mono", "es")
    others = {key("three_link_mono", "vi"), key("three_link_multi", "es"),
              key("three_link_mono", "es", order=4), key("three_link_mono", "es",
                                                         sensitivities=True),
              key("three_link_mono", "es", parameters=("springs[0].stiffness",))}
    assert base not in others and len(others) == 5
    from chaingen import load_reference_scene
    scene = load_reference_scene("three_link_mono")
    other_quadrature = solver_key(scene, "es", 5, sensitivities=False,
                                  build=(compiler(), *DEFAULT_OPTIMISATION))
    other_compiler = solver_key(scene, "es", 3, sensitivities=False,
                                build=("clang", *DEFAULT_OPTIMISATION))
    assert len({base, other_quadrature, other_compiler}) == 3


def test_the_initial_state_does_not_change_the_key():
    import dataclasses

    from chaingen import load_reference_scene
    scene = load_reference_scene("three_link_mono")
    moved = dataclasses.replace(scene, initial_angles=(0.1, 0.2, 0.3))
    build = (compiler(), *DEFAULT_OPTIMISATION)
    assert (solver_key(scene, "es", 3, sensitivities=False, build=build)
            == solver_key(moved, "es", 3, sensitivities=False, build=build))
    assert cache_directory()          # the default cache is where the index lives


def test_the_code_digest_follows_the_templates(tmp_path):
    """An edited template (an editable install's version does not move) changes the digest
    that keys the index: checked on a copy of the templates."""
    import shutil

    import chaingen.templates
    from chaingen.generate.key import folders_digest

    copy = tmp_path / "templates"
    shutil.copytree(Path(chaingen.templates.__file__).parent, copy)
    before = folders_digest([copy])
    assert folders_digest([copy]) == before
    (copy / "Makefile.j2").write_text((copy / "Makefile.j2").read_text() + "\n")
    assert folders_digest([copy]) != before


def test_method_quadrature_and_order_default_to_the_scenes_own():
    """build_solver(scene) builds the solver the scene's [simulation] names (method, K, order)."""
    import dataclasses

    from chaingen import build_solver, load_reference_scene

    scene = load_reference_scene("three_link_mono")

    def own(**simulation):
        return dataclasses.replace(scene, simulation=dataclasses.replace(scene.simulation,
                                                                         **simulation))

    assert build_solver(own(method="vi"), sensitivities=False).manifest["method"] == "vi"
    five = build_solver(own(method="es", quadrature=5), sensitivities=False)
    assert (five.manifest["method"], five.manifest["quadrature"]) == ("es", 5)
    assert five.library_path == build_solver(scene, "es", 5, sensitivities=False).library_path
    assert five.library_path != build_solver(scene, "es", 3, sensitivities=False).library_path
    fourth = build_solver(own(method="midpoint", order=4), sensitivities=False)
    assert (fourth.manifest["method"], fourth.manifest["order"]) == ("midpoint", 4)

def test_the_code_digest_follows_the_runtime_library(tmp_path):
    """An edited chaingen_runtime.c (the runtime library every package compiles) changes the
    digest: the index once served libraries built before such an edit (a .c was not hashed)."""
    import shutil

    import chaingen.runtime
    from chaingen.generate.key import folders_digest

    copy = tmp_path / "runtime"
    shutil.copytree(Path(chaingen.runtime.__file__).parent, copy)
    before = folders_digest([copy])
    source = copy / "c" / "chaingen_runtime.c"
    source.write_text(source.read_text() + "\n")
    assert folders_digest([copy]) != before
