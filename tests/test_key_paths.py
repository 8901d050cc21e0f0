"""One number, one key path: another spelling of a number (leading zeros in an index, non-ASCII
digits, which Python's \\d matches, whitespace around or inside) is refused wherever a path is
read, with the canonical spelling in a one-line message, before anything is built: the scene's
numbers (number_path, which sweep specs use), `--parameters`, build_solver and
Solver.parameter_values. No compiler needed."""
from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from chaingen.errors import SceneError, SettingsError
from chaingen.runtime.keypaths import canonical_path, spelling_error
from chaingen.scene.parameters import compiled_paths, number_path
from chaingen.studies.sweep import parse_spec

from helpers import ROOT, chaingen_in_process, load

SCENE = "three_link_multi"
#: Digits 0-9 in other scripts than ASCII: Arabic-Indic, Devanagari, fullwidth, Bengali.
DIGITS = ("\u0660", "\u0966", "\uff10", "\u09e6")
SPACES = (" ", "\t", "\u00a0", "\u3000", "\n")


def every_number(scene) -> list[str]:
    """The canonical path of every number a study may vary."""
    return (list(compiled_paths(scene)) + [f"initial.angles[{j}]" for j in range(scene.n)]
            + [f"initial.velocities[{j}]" for j in range(scene.n)]
            + ["simulation.dt", "simulation.t_end"])


@st.composite
def spellings(draw):
    """(canonical path of a number of the scene, a spelling of it)."""
    canonical = draw(st.sampled_from(every_number(load(SCENE))))
    pieces = []
    for piece in canonical.replace("[", "\0[").replace(".", "\0.").split("\0"):
        if piece.startswith("["):
            number = piece[1:-1]
            zeros = "0" * draw(st.integers(0, 3))
            base = draw(st.sampled_from((None,) + DIGITS))
            digits = zeros + number
            if base is not None:
                digits = "".join(chr(ord(base) + int(c)) if draw(st.booleans()) else c
                                 for c in digits)
            piece = f"[{digits}]"
        pieces.append(piece)
    spaced = ""
    for piece in pieces:
        spaced += draw(st.sampled_from(("",) * 6 + SPACES)) + piece
    spaced += draw(st.sampled_from(("",) * 6 + SPACES))
    return canonical, spaced


@settings(max_examples=300, deadline=None)
@given(spellings())
def test_one_number_has_one_path(drawn):
    canonical, spelling = drawn
    scene = load(SCENE)
    assert canonical_path(spelling) == canonical
    if spelling == canonical:
        assert number_path(scene, spelling).path == canonical
        assert spelling_error(spelling) is None
        return
    with pytest.raises(SceneError) as refused:
        number_path(scene, spelling, where="axes")
    message = str(refused.value)
    assert f"write {canonical} " in message and "\n" not in message.replace(repr(spelling), "")


@pytest.mark.parametrize("spelling, canonical", [
    ("links[01].mass", "links[1].mass"),
    ("links[\u0661].mass", "links[1].mass"),             # an Arabic-Indic 1
    ("springs[0].offsets[\uff11]", "springs[0].offsets[1]"),
    ("gravity ", "gravity"),
    (" links[1].mass", "links[1].mass"),
    ("links[ 1 ] . mass", "links[1].mass"),
    ("initial.angles[00]", "initial.angles[0]"),
])
def test_other_spellings_are_refused_naming_the_canonical_one(spelling, canonical):
    with pytest.raises(SceneError, match=re.escape(f"write {canonical} ")):
        number_path(load(SCENE), spelling)


@pytest.mark.parametrize("text", ["links[1_0].mass", "links[+1].mass", "links[\u00b9].mass",
                                  "l\u0131nks[1].mass", "links[1]mass", "", "[1]"])
def test_what_is_no_path_names_no_number(text):
    assert canonical_path(text) is None
    with pytest.raises(SceneError, match="names no number"):
        number_path(load(SCENE), text)


def test_a_sweep_refuses_two_spellings_of_one_number_before_the_build():
    for axes in ({"links[1].mass": [1.0, 2.0], "links[01].mass": [3.0]},
                 {"springs[0].stiffness ": [5.0]},
                 {"links[\u0661].mass": [1.0]}):
        with pytest.raises(Exception, match="write (links|springs)") as refused:
            parse_spec({"scene": str(ROOT / "scenes" / "three_link_mono.toml"), "axes": axes})
        assert "\n" not in str(refused.value)


def test_parameters_option_refuses_other_spellings_before_the_build(tmp_path):
    scene = ROOT / "scenes" / "three_link_mono.toml"
    for given_ in ("links[01].mass", "springs[0].stiffness,springs[00].stiffness",
                   "links[1] .mass"):
        result = chaingen_in_process("generate", scene, "--parameters", given_,
                                     "-o", tmp_path / "out", cwd=tmp_path)
        assert result.returncode == 2, result.stderr
        assert "--parameters" in result.stderr and "write " in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "out").exists()
    from chaingen.symbolic.schemes import build_scheme
    with pytest.raises(SettingsError, match=re.escape("write links[1].mass")):
        build_scheme(load("three_link_mono"), "es", 3, parameters=("links[\u0661].mass",))


def test_the_python_api_refuses_other_spellings():
    from test_runtime_guards import fake_solver

    solver = fake_solver(["links[1].mass", "springs[0].stiffness"], [1.0, 10.0], [0.0, 0.0],
                         [False, True])
    assert solver.parameter_values({"links[1].mass": 2.0})[0] == 2.0
    for spelling in ("links[01].mass", "links[1].mass ", "links[\u0661].mass"):
        with pytest.raises(ValueError, match=r"write links\[1\]\.mass"):
            solver.parameter_values({spelling: 2.0})
    with pytest.raises(ValueError, match="has no parameter 'links.2..mass'"):
        solver.parameter_values({"links[2].mass": 2.0})
