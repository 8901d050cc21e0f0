"""Behaviour at the edges that the default run must keep: a run stops with a clear status
instead of writing garbage (docs/extremes.md has the measured study)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chaingen.runtime import NewtonError

from helpers import load, solver_for

pytestmark = pytest.mark.compile


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_a_spring_segment_passing_through_zero_length_stops_the_run(method):
    """collapsing_spring: the segment P_1 P_2 has zero length at theta* = atan(1/0.3), which the
    link, spinning at 3 rad/s from 0.5 rad, reaches between t = 0.25 s and 0.26 s."""
    scene = load("collapsing_spring")
    solver = solver_for("collapsing_spring", method, 3)
    with pytest.raises(NewtonError, match="spring segment") as caught:
        solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=500)
    crossing = (math.atan2(1.0, 0.3) - 0.5) / 3.0
    assert caught.value.status == 6
    assert caught.value.time <= crossing <= caught.value.time + 0.01 + 1e-12
    rows = caught.value.result.samples
    assert len(rows) == caught.value.step and np.all(np.isfinite(rows))


def test_the_same_spring_runs_when_it_stays_clear_of_zero_length():
    result = solver_for("collapsing_spring", "es", 3).simulate(
        [0.5], [-1.0], dt=0.01, n_steps=100)     # spinning away from theta*
    assert np.all(np.isfinite(result.samples))


def test_a_single_step_through_the_collapse_raises():
    solver = solver_for("collapsing_spring", "es", 3)
    x0 = solver.initial_state([1.27], [3.0])
    with pytest.raises(NewtonError, match="spring segment"):
        solver.step(x0, dt=0.01)
