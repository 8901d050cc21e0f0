"""The C entry points of one fixed step refuse adaptive tolerances themselves: step,
step_sensitivities and control_torques called straight through the loader's ctypes binding
(bypassing the Python methods' own refusal) with rtol or atol other than 0 return BAD_ARGUMENT,
outputs untouched. Before, C took a plain step of dt with them and said nothing."""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest

from chaingen.runtime.contract import STATUS_CODES

from helpers import solver_for

pytestmark = pytest.mark.compile

DT = 0.01
POINTER = ctypes.POINTER(ctypes.c_double)


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(POINTER)


@pytest.fixture(scope="module")
def solvers():
    return {"sensitivities": solver_for("three_link_gravity", sensitivities=True),
            "control": solver_for("four_link_pbc")}


def _call(solver, entry: str, name: str | None = None, value: float = 0.0):
    """(status, x1, the entry's other output) of one call with the package's default options,
    the field `name` of the C struct set to `value` (no Python check on the way); the outputs
    start as 7.0."""
    x0 = solver.initial_state(np.full(solver.n, 0.3), np.zeros(solver.n))
    x1 = np.full(solver.nx, 7.0)
    u = np.zeros(max(solver.nu, 1))
    c_options = solver.newton_options().as_c()
    if name:
        setattr(c_options, name, value)
    common = dict(x0=_pointer(x0), u=_pointer(u) if solver.nu else None,
                  p=None, dt=DT, x1=_pointer(x1), options=ctypes.byref(c_options),
                  iterations=None)
    if entry == "step":
        other = np.full(2, 7.0)
        status = solver._leased("step", flows=_pointer(other), **common)
    elif entry == "control_torques":
        other = np.full(solver.nu, 7.0)
        status = solver._leased("control_torques", tau=_pointer(other), **common)
    else:
        ns = 2 * solver.n
        other = np.full(ns * ns, 7.0)
        ds_du = np.full(max(ns * solver.nu, 1), 7.0)
        status = solver._leased("step_sensitivities", ds_ds=_pointer(other),
                                ds_du=_pointer(ds_du) if solver.nu else None, ds_dp=None,
                                **common)
    return status, x1, other


CASES = [("sensitivities", "step"), ("sensitivities", "step_sensitivities"),
         ("control", "step"), ("control", "control_torques")]


@pytest.mark.parametrize("package, entry", CASES)
@pytest.mark.parametrize("name", ["rtol", "atol"])
@pytest.mark.parametrize("value", [1e-8, 1.0, -1e-8, math.nan])
def test_a_fixed_step_entry_point_refuses_adaptive_tolerances(solvers, package, entry, name,
                                                              value):
    status, x1, other = _call(solvers[package], entry, name, value)
    assert status == STATUS_CODES["BAD_ARGUMENT"]
    assert np.all(x1 == 7.0) and np.all(other == 7.0)


@pytest.mark.parametrize("package, entry", CASES)
def test_with_both_zero_the_entry_point_steps(solvers, package, entry):
    status, x1, other = _call(solvers[package], entry)
    assert status == STATUS_CODES["OK"]
    assert np.all(np.isfinite(x1)) and not np.all(x1 == 7.0)
