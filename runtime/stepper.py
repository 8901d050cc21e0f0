"""A control loop's step in joint space: the state kept in C's layout, its angles and rates in
preallocated arrays, one step per call with no allocation.

`Solver.step` takes and returns the scheme's internal state and allocates its results, which
suits verification; a controller written in Python wants (phi, omega) after every step at the
least cost. A Stepper keeps the internal state (so the Newton warm start carries from step to
step as in `simulate`), steps it in place and writes phi and omega, the energy and the
constraint error into arrays it owns. Its C calls are bound once, with their arguments.

Threads: a Stepper has a C workspace of its own and is used by one thread at a time; make one
per thread (they share the loaded library, which keeps no mutable state). A step or reset
begun while another thread's is under way is refused with a RuntimeError (two at once would
overwrite each other's workspace and state: wrong numbers, no error). Torques assigned to `u`
from another thread while a step is under way are taken as a digital controller's command
register is: the step under way keeps the torques it began with (zero-order hold over the
step), and the new ones hold from the next step on (`u` reads them at once). Before, the C
step read `u` where the assignment wrote it, so its Newton iterations after the assignment
solved with the new torques: a step with neither torques, and no error. Change `u` by
assigning it; the array `u` returns is the held one, changed in place only by its own thread.
"""
from __future__ import annotations

import ctypes
import threading

import numpy as np

from . import contract
from .errors import NewtonError
from .interface import finite, real_array, real_number

_DOUBLE = np.dtype(np.float64)     # of a u taken as it is
_BAD_ARGUMENT = contract.STATUS_CODES["BAD_ARGUMENT"]


def _address(buffer) -> ctypes.c_void_p:
    """A pointer argument for a call without argtypes: a numpy array's data or a ctypes
    object's address."""
    if isinstance(buffer, np.ndarray):
        return ctypes.c_void_p(buffer.ctypes.data)
    return ctypes.c_void_p(ctypes.addressof(buffer))


def _bound(solver, name: str, arguments: dict):
    """<prefix>_<name> and its arguments in the contract's order, for calls without argtypes:
    ctypes then converts nothing per call (a call costs a third of one with argtypes), so
    every argument must already be of its C type: c_void_p for pointers (NULL: None),
    c_double for doubles, c_int for the sizes nu and np (the package's unless given)."""
    function = solver._lib[f"{solver.prefix}_{name}"]    # an object of its own: no argtypes
    function.restype = ctypes.c_int
    sizes = {"nu": ctypes.c_int(solver.nu), "np": ctypes.c_int(len(solver.parameters))}
    values = []
    for parameter in contract.ENTRY_POINTS_BY_NAME[name].parameters:
        value = arguments.get(parameter.name, sizes.get(parameter.name))
        if parameter.c_type.endswith("*"):
            value = None if value is None else _address(value)
        elif parameter.c_type not in ("double", "int"):
            raise ValueError(f"{name}: no raw argument of C type {parameter.c_type!r} "
                             f"({parameter.name})")
        values.append(value)
    return function, tuple(values)


class Stepper:
    """Steps one chain in joint space; see the module docstring. Made by `Solver.stepper`.

    After construction and after every `step`: `phi`, `omega` (n,) are the joint angles
    (wrapped to (-pi, pi], as in a sample row) and rates, `t` the time (t0 + k dt), `energy` and
    `constraint_error` those of the state, `iterations` the last step's Newton iterations,
    and, for a scene with energy flows, `input_work` and `dissipated` their sums since the
    start. The arrays are updated in place: keep a copy to remember a value.
    """

    def __init__(self, solver, phi, omega, dt: float, options=None, parameters=None):
        self.solver = solver
        n, nu = solver.n, solver.nu
        self.phi, self.omega = np.empty(n), np.empty(n)
        self._u = np.zeros(nu)
        # Torques assigned to u: a new array, never changed once stored, taken by the next
        # step as it begins (_take_pending), so that an assignment from another thread during
        # a step leaves that step's torques alone; the lock orders the assignments that store
        # and the step that takes them (a step without one reads the attribute alone).
        self._pending: np.ndarray | None = None
        self._pending_lock = threading.Lock()
        self._inputs_shape = (nu,) if nu else None    # of a u taken as it is
        # t = base + count dt, as simulate's t0 + k dt (a sum of dt would drift from it in the
        # last bits); a new dt starts a new base.
        self._base, self._count = 0.0, 0
        self.energy = self.constraint_error = 0.0
        self.iterations = 0
        self.input_work = self.dissipated = 0.0
        self._states = (np.empty(solver.nx), np.empty(solver.nx))
        self._flows = np.zeros(2)
        self._scalars = np.zeros(2)
        # A package without run-time parameters refuses any given, as simulate does (a
        # Stepper ran with the scene's own numbers, whatever it was given).
        solver._p(parameters)
        self._p_values = (solver.parameter_values(parameters) if solver.parameters
                          else np.zeros(0))
        self._workspace = ctypes.create_string_buffer(solver._workspace_size)
        self._options = solver._fixed_step_options(options, "Stepper")
        # The right to step: one token, taken by the step (reset, change of dt) under way.
        # list.pop and list.append are atomic: a lock that costs a third of a Lock's
        # acquire(False) and release (a step's Python cost is some microseconds).
        tokens = [True]
        self._take_token, self._give_token = tokens.pop, tokens.append
        self._dt = ctypes.c_double(0.0)
        self.dt = dt
        self._iterations = ctypes.c_int(0)
        self._flowing = solver.energy_flows
        common = dict(p=self._p_values if solver.parameters else None,
                      workspace=self._workspace, u=self._u if nu else None)
        # Two argument lists each, the states' roles swapped: a step writes the other state.
        self._step_arguments, self._outputs_arguments = [], []
        for current, following in ((0, 1), (1, 0)):
            self._step_function, arguments = _bound(solver, "step", dict(
                common, x0=self._states[current], x1=self._states[following], dt=self._dt,
                flows=self._flows, options=self._options, iterations=self._iterations))
            self._step_arguments.append(arguments)
            self._outputs_function, arguments = _bound(solver, "outputs", dict(
                common, x=self._states[following], phi=self.phi, omega=self.omega,
                energy=self._scalars[:1], constraint_error=self._scalars[1:]))
            self._outputs_arguments.append(arguments)
        self.reset(phi, omega)

    @property
    def u(self) -> np.ndarray:
        """The torques of the next step (nu,), held until changed (assigning copies). Assigned
        from another thread while a step is under way, they hold from the next step on: the
        step under way keeps the torques it began with (module docstring)."""
        pending = self._pending
        return self._u if pending is None else pending

    @u.setter
    def u(self, value) -> None:
        # Stored aside and taken by the next step as it begins: never written where a step
        # under way (another thread's) reads its torques, and never refused.
        array = np.array(self._checked_inputs(value), dtype=float)
        with self._pending_lock:
            self._pending = array

    def _checked_inputs(self, value) -> np.ndarray:
        """value as u: exactly nu torques (no scalar spread over the joints, as Solver.step)."""
        u = self._u
        if not u.shape[0]:
            raise ValueError(f"{self.solver.prefix} has no actuated joints; u must be None")
        array = real_array(value, "u")
        if array.shape != u.shape:
            raise ValueError(f"u must have {u.shape[0]} entries (one per actuated joint), got "
                             f"shape {array.shape}")
        return array

    def _take_pending(self) -> None:
        """Hold the torques assigned since the last step began from now on (the step's token
        held: no C call reads self._u meanwhile)."""
        with self._pending_lock:
            pending, self._pending = self._pending, None
        if pending is not None:
            self._u[:] = pending

    @property
    def dt(self) -> float:
        """The step length (s); may be changed between steps."""
        return self._dt.value

    @dt.setter
    def dt(self, value: float) -> None:
        value = real_number(value, "dt")
        if not (0.0 < value < np.inf):
            raise ValueError(f"dt: must be > 0 and finite, got {value!r}")
        self._take()
        try:
            self._base, self._count = self.t, 0
            self._dt.value = value
        finally:
            self._give_token(True)

    @property
    def t(self) -> float:
        """The time of the state (s)."""
        return self._base + self._count * self._dt.value

    @property
    def state(self) -> np.ndarray:
        """A copy of the scheme's internal state (for Solver.step, step_sensitivities)."""
        return self._states[self._current].copy()

    def _take(self) -> None:
        """Take the Stepper's token without waiting (the caller gives it back): a RuntimeError
        if another thread's step, reset or change of dt holds it."""
        try:
            self._take_token()
        except IndexError:
            raise self._busy() from None

    def _busy(self) -> RuntimeError:
        return RuntimeError(f"{self.solver.prefix} Stepper: used by two threads at once (a "
                            "Stepper is for one thread at a time: make one per thread)")

    def reset(self, phi, omega, t: float = 0.0) -> None:
        """Start again from joint space (phi, omega) at time t, with no Newton history."""
        t = real_number(t, "t")
        if not np.isfinite(t):     # every later t would be NaN or Inf
            raise ValueError(f"t: must be finite, got {t!r}")
        self._take()
        try:
            self._reset(phi, omega, t)
        finally:
            self._give_token(True)

    def _reset(self, phi, omega, t: float) -> None:
        solver = self.solver
        phi = finite(real_array(phi, "phi", (solver.n,)), "phi")
        omega = finite(real_array(omega, "omega", (solver.n,)), "omega")
        x = solver.initial_state(phi, omega, self._p_values if solver.parameters else None)
        solver._call("workspace_init", workspace=self._workspace)
        # _current: which of the two states is the chain's; the step from state c writes
        # state 1 - c, and _outputs_arguments[c] read state 1 - c.
        self._states[0][:] = x
        self._current = 0
        status = self._outputs_function(*self._outputs_arguments[1])
        if status:
            raise NewtonError(f"{solver.prefix}_outputs: {solver.status_message(status)}",
                              status=status)
        self.energy, self.constraint_error = float(self._scalars[0]), float(self._scalars[1])
        self._base, self._count = t, 0
        self.input_work = self.dissipated = 0.0
        self.iterations = 0

    def step(self, u=None) -> None:
        """One step of dt with torques u (actuated scenes; None: keep `self.u`). Updates phi,
        omega, t and the rest in place; raises NewtonError if the step fails (the state is
        then that before the step)."""
        try:
            self._take_token()
        except IndexError:      # another thread's step is under way
            raise self._busy() from None
        try:
            if self._pending is not None:    # u assigned since the last step began
                self._take_pending()
            if u is not None:
                if type(u) is np.ndarray and u.dtype is _DOUBLE and u.shape == self._inputs_shape:
                    self._u[:] = u
                else:
                    self._u[:] = self._checked_inputs(u)
            current = self._current
            status = self._step_function(*self._step_arguments[current])
            if status:
                solver = self.solver
                if status == _BAD_ARGUMENT:     # C's word for a NaN or Inf in u
                    finite(self._u, "u")
                raise NewtonError(f"step at t = {self.t:.6g} s failed after "
                                  f"{self._iterations.value} Newton iterations: "
                                  f"{solver.status_message(status)}", status=status)
            self._current = 1 - current
            self._count += 1
            status = self._outputs_function(*self._outputs_arguments[current])
            if status:
                raise NewtonError(f"{self.solver.prefix}_outputs at t = {self.t:.6g} s: "
                                  f"{self.solver.status_message(status)}", status=status)
            self.iterations = self._iterations.value
            scalars = self._scalars
            self.energy, self.constraint_error = scalars[0], scalars[1]
            if self._flowing:
                self.input_work += self._flows[0]
                self.dissipated += self._flows[1]
        finally:
            self._give_token(True)
