"""The compiled peers (codegen/reference/compiled_peers.py): runs against the SciPy peer's
reference, the records they return, and their errors.

Each method on three_link_mono must agree with scipy_peer.reference_solution at t = 1 s; the
record's counts, samples and energies must be consistent with each other, and the numba
warm-up must leave no trace in the timed run's counts. A missing numbalsoda (the `peers` extra)
is an error that names the extra, found before anything is built (fast tier), and the bench
turns it into a note.

The `peers` extra is not in the `test` one (numbalsoda has no wheel: it needs gfortran). Where it
is missing, the tests that run numbalsoda skip naming it, before anything is built; with
CHAINGEN_REQUIRE_TOOLS=1 (.ci/run, which installs it) they fail instead.
"""
from __future__ import annotations

import dataclasses
import functools
import os
import sys

import numpy as np
import pytest

from chaingen.errors import ScipyPeerError
from chaingen.reference import compiled_peers
from chaingen.reference.compiled_peers import (
    CVODES_METHODS,
    DEFAULT_SAMPLE_INTERVAL,
    METHODS,
    NUMBALSODA_METHODS,
    simulate_compiled,
)
from chaingen.studies.bench.config import COMPILED_TOLERANCES, bench_config

from helpers import load

SCENE = "three_link_mono"


def wrapped(difference):
    return (np.asarray(difference) + np.pi) % (2 * np.pi) - np.pi


#: Why a numbalsoda test does not run where the extra is missing.
MISSING_PEERS = ("numbalsoda is not installed (the `peers` extra, not in `test`: pip install -e "
                 "'.[peers]', which builds it from source with gfortran)")


def require_peer(method):
    """Skip a test of a numbalsoda method where the `peers` extra is missing (fail with
    CHAINGEN_REQUIRE_TOOLS=1, so CI cannot pass by skipping); called first, before any build."""
    if method not in NUMBALSODA_METHODS or compiled_peers.numbalsoda_available():
        return
    if os.environ.get("CHAINGEN_REQUIRE_TOOLS") == "1":
        pytest.fail(f"{MISSING_PEERS} (CHAINGEN_REQUIRE_TOOLS=1)", pytrace=False)
    pytest.skip(MISSING_PEERS)


@functools.cache
def reference_at_one_second():
    """Built on first use (not a fixture, which would build before a test could skip)."""
    from chaingen.reference.scipy_peer import reference_solution
    return reference_solution(load(SCENE), 1.0)


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
def test_run_agrees_with_the_reference(method):
    require_peer(method)
    angles, velocities = reference_at_one_second()
    run = simulate_compiled(load(SCENE), method, 1e-10, 1e-10, 1.0)
    assert np.abs(wrapped(run.final_angles - angles)).max() <= 1e-6
    assert np.abs(run.final_velocities - velocities).max() <= 1e-5
    # the record: default samples every DEFAULT_SAMPLE_INTERVAL, H at each, the error from them
    count = round(1.0 / DEFAULT_SAMPLE_INTERVAL) + 1
    np.testing.assert_allclose(run.sample_times, np.linspace(0.0, 1.0, count))
    assert run.energies.shape == (count,)
    assert run.energies[0] == pytest.approx(run.initial_energy, abs=1e-14)
    assert run.max_energy_error == pytest.approx(np.abs(run.energies - run.initial_energy).max())
    assert 0 < run.max_energy_error <= 1e-7
    assert run.cpu_time > 0 and run.wall_time > 0 and np.isfinite(run.cpu_time)
    assert (run.method, run.rtol, run.atol, run.t_end, run.status) == (method, 1e-10, 1e-10,
                                                                       1.0, 0)
    assert run.nfev > 0
    if method in CVODES_METHODS:
        assert 0 < run.n_steps <= run.nfev
    else:
        assert (run.n_steps, run.njev, run.nlu) == (0, 0, 0)   # not reported by numbalsoda
    if method == "CVODES-BDF":
        assert run.njev > 0 and run.nlu > 0
    assert not run.final_angles.flags.writeable


@pytest.mark.compile
@pytest.mark.parametrize("method", NUMBALSODA_METHODS)
def test_numba_warm_up_is_not_counted(method, monkeypatch):
    """A first run (a fresh cfunc, compiled and warmed up by numba) and a second one count the
    same right-hand sides and end in the same state: the warm-up run is not part of it."""
    require_peer(method)
    monkeypatch.setattr(compiled_peers, "_NUMBA_RHS", {})
    scene = load(SCENE)
    first = simulate_compiled(scene, method, 1e-8, 1e-8, 0.5)
    assert [method in rhs.warmed for rhs in compiled_peers._NUMBA_RHS.values()] == [True]
    second = simulate_compiled(scene, method, 1e-8, 1e-8, 0.5)
    assert first.nfev == second.nfev > 0
    np.testing.assert_array_equal(first.final_angles, second.final_angles)


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
def test_sample_times_are_the_requested_ones(method):
    require_peer(method)
    run = simulate_compiled(load(SCENE), method, 1e-8, 1e-8, 2.0, [0.5, 1.0, 1.5])
    np.testing.assert_array_equal(run.sample_times, [0.5, 1.0, 1.5])
    assert run.energies.shape == (3,)
    full = simulate_compiled(load(SCENE), method, 1e-8, 1e-8, 2.0, [2.0])
    np.testing.assert_allclose(run.final_angles, full.final_angles, atol=1e-6)


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
def test_non_finite_right_hand_side_fails(method):
    """Rates so large that the right-hand side overflows: a one-line error, no endless run."""
    require_peer(method)
    scene = load(SCENE)
    scene = dataclasses.replace(scene, initial_velocities=(1e200,) * scene.n)
    with pytest.raises(ScipyPeerError, match=f"three-link-mono: {method}.*(not finite|CVODES)"
                       ) as caught:
        simulate_compiled(scene, method, 1e-8, 1e-8, 1.0)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("arguments, fragment", [
    (("RK99", 1e-8, 1e-8, 1.0), "'RK99'"),
    (("CVODES-BDF", 0.0, 1e-8, 1.0), "rtol"),
    (("CVODES-BDF", 1e-8, 1e-8, float("inf")), "t_end"),
])
def test_bad_arguments_are_named(arguments, fragment):
    with pytest.raises(ScipyPeerError, match=fragment):
        simulate_compiled(load(SCENE), *arguments)


def test_bad_sample_times_are_named():
    with pytest.raises(ScipyPeerError, match="sample_times"):
        simulate_compiled(load(SCENE), "CVODES-BDF", 1e-8, 1e-8, 1.0, [0.5, 0.2])


@pytest.mark.parametrize("method", NUMBALSODA_METHODS)
def test_missing_numbalsoda_names_the_extra(method, monkeypatch):
    monkeypatch.setitem(sys.modules, "numbalsoda", None)    # import numbalsoda raises
    assert not compiled_peers.numbalsoda_available()
    with pytest.raises(ScipyPeerError, match=r"numbalsoda.*pip install -e '\.\[peers\]'"):
        simulate_compiled(load(SCENE), method, 1e-8, 1e-8, 1.0)


def test_bench_notes_a_missing_numbalsoda(tmp_path, monkeypatch):
    from chaingen.studies.bench.runs import COMPILED_FAMILY, compiled_rows

    monkeypatch.setitem(sys.modules, "numbalsoda", None)
    config = dataclasses.replace(bench_config(quick=True, out=tmp_path / "b.md"),
                                 compiled_tolerances=tuple((method, (1e-6,)) for method
                                                           in NUMBALSODA_METHODS))
    notes = []
    rows = compiled_rows(load(SCENE), SCENE, config, 1.0, (None, None), notes.append)
    assert [row.method for row in rows] == list(NUMBALSODA_METHODS)
    assert all(row.family == COMPILED_FAMILY and "numbalsoda is not installed" in row.failure
               and "[peers]" in row.failure for row in rows)
    assert len(notes) == 2


def test_the_bench_names_every_compiled_peer():
    assert tuple(method for method, _ in COMPILED_TOLERANCES) == METHODS
