"""Load a built chaingen package and drive it from Python with numpy arrays.

Python calls C once per simulation (`simulate`, open loop or closed by a controller), not once
per step; a control loop written in Python steps through a `Stepper` (runtime/stepper.py), and
the per-step entry points (`step`, `residual_jacobian`, ...) are there for verification and
studies, their arguments in C's order. The C signatures are
not written here: they come from the package's manifest, which records the parameter list of
every entry point it exports (chaingen.runtime.contract).

Threads and callbacks: one Solver may be used from any number of threads at once, and from
inside its own callbacks. Each thread gets a C workspace of its own on its first call (ctypes
releases the GIL during the C call, so a shared one would be overwritten), so a thread's steps
see only its own Newton history (warm start, kept Jacobian) and its results equal those of the
same calls made alone. A running call owns its workspace: a call made while it runs (a
progress callback calling `outputs` or `step`, a controller calling `simulate` for a rollout)
gets a spare workspace with no Newton history (runtime/workspaces.py), and the running call's
results are those it gives undisturbed.

Interrupts: Ctrl-C, an exception of a progress callback and a StopSignal end a running simulate
after its current step (runtime/runs.py).
"""
from __future__ import annotations

import ctypes
import dataclasses
import json
import operator
import time
from pathlib import Path

import numpy as np

from . import contract
from .build import build_shared_library
from .controller import controller_address
from .errors import NewtonError
from .interface import (
    ControlStruct,
    NewtonOptions,
    StatsStruct,
    ctypes_type,
    finite,
    held_angles,
    positive_step,
    real_array,
    step_length,
)
from .parameters import no_values, parameter_vector
from .parameters import parameter_bounds as _parameter_bounds
from .results import ControlledStep, Sensitivities, SimulationResult, StepResult, storage_of
from .runs import StopSignal, check_watchers, run_watched
from .stepper import Stepper
from .workspaces import Workspaces

__all__ = ["MAX_SAMPLE_BYTES", "Solver", "StopSignal"]

_double_p = ctypes.POINTER(ctypes.c_double)
#: Samples (and recorded torques) are held in memory: a bigger run is refused before allocating.
MAX_SAMPLE_BYTES = 4 * 2 ** 30


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(_double_p)


def _vector(values, size: int, name: str) -> np.ndarray:
    """`size` finite real numbers (a state, posture, rates or inputs)."""
    return finite(real_array(values, name, (size,)), name)


class Solver:
    """A loaded package: its manifest (sizes, layouts, entry points) and its C entry points."""

    def __init__(self, library: Path, manifest: dict, *, build_hash: str | None = None):
        self.library_path = Path(library)
        self.manifest = manifest
        self.build_hash = build_hash
        self.prefix = manifest["prefix"]
        self.n = manifest["n_joints"]
        self.nx = manifest["nx"]
        self.nz = manifest["nz"]
        self.nsample = manifest["nsample"]
        self.actuated_joints = tuple(manifest["actuated_joints"])
        self.nu = len(self.actuated_joints)
        self.energy_flows = bool(manifest["energy_flows"])
        self.has_sensitivities = bool(manifest["sensitivities"])
        self.segment_tolerance = manifest.get("segment_tolerance")
        #: The run-time parameters by key path, with the scene's own values as defaults.
        self.parameters = tuple(entry["path"] for entry in manifest["parameters"])
        self.default_parameters = np.array([entry["value"] for entry in manifest["parameters"]],
                                           dtype=float)
        self._bounds = _parameter_bounds(manifest["parameters"])
        self._lib = ctypes.CDLL(str(self.library_path))
        # The one set of signatures every package has (the contract's), bound where the
        # package has the function (the others return UNAVAILABLE).
        features = contract.Features.from_manifest(manifest)
        self._entry_points = {entry.name: self._declare(entry)
                              for entry in contract.ENTRY_POINTS if features.has(entry.when)}
        if build_hash is not None:
            built = self._call("build_hash").decode()
            if built != build_hash:
                raise ValueError(f"{self.library_path}: built as {built!r}, not {build_hash!r}")
        self._workspace_size = self._call("workspace_size")
        self._workspaces = Workspaces(self._workspace_size, lambda workspace: self._call(
            "workspace_init", workspace=workspace))
        self.default_options = NewtonOptions(**manifest["newton_defaults"])

    @classmethod
    def from_files(cls, files: dict[str, str], **build_options) -> Solver:
        manifest = json.loads(files[contract.MANIFEST])
        build_options.setdefault("source_flags", {
            name: tuple(flags) for name, flags in manifest["source_flags"].items()})
        library = build_shared_library(manifest["prefix"], files, manifest["sources"],
                                       **build_options)
        return cls(library.path, manifest, build_hash=library.build_hash)

    @classmethod
    def from_directory(cls, directory, **build_options) -> Solver:
        """Build and load the package in `directory`: the files its manifest lists."""
        directory = Path(directory)
        manifest = json.loads((directory / contract.MANIFEST).read_text())
        files = {name: (directory / name).read_text() for name in manifest["files"]}
        return cls.from_files(files, **build_options)

    # -- the C functions ----------------------------------------------------------------------

    def _declare(self, entry: contract.EntryPoint):
        """The ctypes function of an entry point, with the signature every package has."""
        function = getattr(self._lib, f"{self.prefix}_{entry.name}")
        function.restype = ctypes_type(entry.returns, self.prefix)
        function.argtypes = [ctypes_type(contract.resolved(p.c_type, self.prefix), self.prefix)
                             for p in entry.parameters]
        return function, tuple(p.name for p in entry.parameters)

    def newton_options(self, options: NewtonOptions | dict | None = None) -> NewtonOptions:
        """Newton options: given ones as they are, or the package's defaults with the fields
        of a dict (contract field names) replaced."""
        if isinstance(options, NewtonOptions):
            return options
        fields = {field.name: field for field in contract.NEWTON_OPTIONS}
        unknown = set(options or {}) - set(fields)
        if unknown:
            raise ValueError(f"no Newton option {', '.join(sorted(unknown))} (known: "
                             f"{', '.join(fields)})")
        return dataclasses.replace(self.default_options, **(options or {}))   # checks them

    def has_entry_point(self, name: str) -> bool:
        """Whether the package has `name` (every package exports every entry point; one it
        was generated without returns UNAVAILABLE)."""
        return name in self._entry_points

    def _call(self, name: str, **arguments):
        """Call <prefix>_<name> with its arguments by parameter name. The sizes nu and np are
        the package's unless given; a pointer not given is NULL (u of an unactuated scene,
        flows)."""
        function, parameters = self._entry_points[name]
        sizes = {"nu": self.nu, "np": len(self.parameters)}
        return function(*[arguments.get(parameter, sizes.get(parameter))
                          for parameter in parameters])

    @property
    def _workspace(self):
        """The calling thread's own workspace, for a direct `_call` (tests)."""
        return self._workspaces.home()

    def _serve(self, entry: str, arguments: dict) -> int:
        """simulate's C run, in whichever thread runs it (a callback's calls get spares)."""
        self._workspaces.serve()
        return self._call(entry, **arguments)

    def _leased(self, name: str, **arguments):
        """`_call` in a workspace this call holds alone while it runs (runtime/workspaces.py):
        the thread's own, or a spare if a call of the thread is running (a callback's)."""
        workspace, home = self._workspaces.lease()
        try:
            return self._call(name, workspace=workspace, **arguments)
        finally:
            self._workspaces.release(workspace, home)

    def _check(self, status: int, what: str) -> None:
        if status:
            raise NewtonError(f"{self.prefix}_{what}: {self.status_message(status)}",
                              status=status)

    def status_message(self, status: int) -> str:
        return contract.status_message(status, self.segment_tolerance)

    # -- state maps ---------------------------------------------------------------------------

    def reset(self) -> None:
        """Forget the calling thread's Newton state carried between steps (warm start, reused
        Jacobian). Refused inside a callback of a running call of this thread, whose workspace
        it is (the callback's own calls start with no Newton history anyway)."""
        if self._workspaces.home_busy():
            raise RuntimeError(f"{self.prefix}: reset() inside a callback of a running call: "
                               "the thread's workspace is that call's (a callback's calls start "
                               "with no Newton history)")
        self._call("workspace_init", workspace=self._workspaces.home())

    def initial_state(self, phi, phidot, parameters=None) -> np.ndarray:
        phi, x = held_angles(_vector(phi, self.n, "phi"), "phi"), np.empty(self.nx)
        self._check(self._leased("initial_state", phi=_pointer(phi),
                               p=self._p(parameters),
                               phidot=_pointer(_vector(phidot, self.n, "phidot")),
                               x=_pointer(x)), "initial_state")
        return x

    def outputs(self, x, parameters=None) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(phi, omega, energy, constraint error) of a state."""
        phi, omega, scalars = np.empty(self.n), np.empty(self.n), np.empty(2)
        self._check(self._leased("outputs", x=_pointer(_vector(x, self.nx, "x")),
                               p=self._p(parameters),
                               phi=_pointer(phi), omega=_pointer(omega),
                               energy=_pointer(scalars[:1]),
                               constraint_error=_pointer(scalars[1:])), "outputs")
        return phi, omega, float(scalars[0]), float(scalars[1])

    def parameter_values(self, parameters=None) -> np.ndarray:
        """The parameter vector p: the defaults, a full sequence in the order of
        `self.parameters`, or a mapping of paths (a dict, a pandas Series indexed by path;
        each path in its one spelling, as `self.parameters` has it: chaingen.runtime.keypaths)
        whose values replace the defaults, read by name (runtime/parameters.py). A value the
        scene format refuses (a mass <= 0, a stiffness < 0, NaN, a bool, ...) is refused."""
        return parameter_vector(parameters, self.parameters, self.default_parameters,
                                self._bounds, self.prefix)

    def _p(self, parameters):
        """The p argument: a pointer for a package with parameters, else None (none)."""
        if not self.parameters:
            if parameters is not None and not no_values(parameters):
                raise ValueError(f"{self.prefix} takes no parameters")
            return None
        return _pointer(self.parameter_values(parameters))

    def _inputs(self, u):
        """The u argument of a step function: a pointer for an actuated scene, else None (the
        package has no such parameter)."""
        if not self.nu:
            if u is not None and np.size(u):
                raise ValueError(f"{self.prefix} has no actuated joints; u must be None")
            return None
        if u is None:
            u = np.zeros(self.nu)
        return _pointer(_vector(u, self.nu, "u"))

    def residual(self, z, x0, u=None, dt: float | None = None, *,
                 parameters=None) -> np.ndarray:
        """F(z; x0, u, dt): the arguments in C's order."""
        dt = step_length(dt, "residual")
        out = np.empty(self.nz)
        self._check(self._leased("residual", z=_pointer(real_array(z, "z", (self.nz,))),
                               p=self._p(parameters),
                               x0=_pointer(_vector(x0, self.nx, "x0")), u=self._inputs(u),
                               dt=dt, residual=_pointer(out)),
                    "residual")
        return out

    def residual_jacobian(self, z, x0, u=None, dt: float | None = None, *,
                          parameters=None) -> tuple[np.ndarray, np.ndarray]:
        """(F, dF/dz) at z; the arguments in C's order."""
        dt = step_length(dt, "residual_jacobian")
        residual, jacobian = np.empty(self.nz), np.empty(self.nz * self.nz)
        self._check(self._leased("residual_jacobian", z=_pointer(real_array(z, "z", (self.nz,))),
                               p=self._p(parameters),
                               x0=_pointer(_vector(x0, self.nx, "x0")), u=self._inputs(u),
                               dt=dt, residual=_pointer(residual),
                               jacobian=_pointer(jacobian)), "residual_jacobian")
        return residual, jacobian.reshape((self.nz, self.nz), order="F")

    def holding_torques(self, phi, parameters=None) -> np.ndarray:
        """dV/dphi: the joint torques that hold the chain still at phi (actuated scenes)."""
        if not self.has_entry_point("holding_torques"):
            raise ValueError(f"{self.prefix} has no actuated joints: no holding_torques")
        tau = np.empty(self.n)
        self._check(self._leased("holding_torques", phi=_pointer(_vector(phi, self.n, "phi")),
                               p=self._p(parameters),
                               tau=_pointer(tau)), "holding_torques")
        return tau

    # -- steps --------------------------------------------------------------------------------

    def stepper(self, phi, omega, dt: float, *, options: NewtonOptions | dict | None = None,
                parameters=None) -> Stepper:
        """A Stepper from joint space (phi, omega): steps of dt in a Python control loop at
        the least cost, phi and omega updated in place (runtime/stepper.py)."""
        return Stepper(self, phi, omega, dt, options, parameters)

    def _fixed_step_options(self, options, what: str):
        """The C options of a step of the given dt (step, step_sensitivities, a Stepper):
        adaptive tolerances, which only simulate's loop applies, are refused."""
        chosen = self.newton_options(options)
        if chosen.rtol or chosen.atol:
            raise ValueError(f"{what}: rtol and atol (adaptive steps) apply to simulate only; "
                             f"a step takes the dt it is given (got rtol={chosen.rtol:g}, "
                             f"atol={chosen.atol:g})")
        return chosen.as_c()

    def _step_failed(self, status: int, iterations: int) -> NewtonError:
        return NewtonError(f"step failed after {iterations} Newton iterations: "
                           f"{self.status_message(status)}", status=status)

    def step(self, x0, u=None, dt: float | None = None, *,
             options: NewtonOptions | dict | None = None, parameters=None) -> StepResult:
        """One step from the state x0 with inputs u (actuated scenes; None: zeros), the
        arguments in C's order. Raises NewtonError if it fails. For a control loop in joint
        space, `stepper` costs less a step."""
        dt = step_length(dt, "step")
        x1, iterations, flows = np.empty(self.nx), ctypes.c_int(0), np.zeros(2)
        c_options = self._fixed_step_options(options, "step")
        status = self._leased("step", x0=_pointer(_vector(x0, self.nx, "x0")),
                              u=self._inputs(u), p=self._p(parameters),
                              dt=dt, x1=_pointer(x1), flows=_pointer(flows),
                              options=ctypes.byref(c_options),
                              iterations=ctypes.byref(iterations))
        if status:
            raise self._step_failed(status, iterations.value)
        return StepResult(x1, iterations.value, float(flows[0]), float(flows[1]))

    def control_torques(self, x0, u=None, dt: float | None = None, *,
                        options: NewtonOptions | dict | None = None,
                        parameters=None) -> ControlledStep:
        """The step `step` takes from x0 (the same workspace history: x1 and the iterations are
        bitwise step's), and tau, the torque each actuated joint applies over it as the
        scheme's control law determines it inside the step; the arguments in C's order.
        Raises NewtonError if the step fails, and also where step would split it into halves
        (status NOT_CONVERGED: no single torque over dt); ValueError for a package without a
        control law."""
        dt = step_length(dt, "control_torques")
        if not self.has_entry_point("control_torques"):
            raise ValueError(f"{self.prefix} has no control law: no control_torques (its C "
                             "function returns UNAVAILABLE)")
        tau, x1, iterations = np.empty(self.nu), np.empty(self.nx), ctypes.c_int(0)
        c_options = self._fixed_step_options(options, "control_torques")
        status = self._leased("control_torques", x0=_pointer(_vector(x0, self.nx, "x0")),
                              u=self._inputs(u), p=self._p(parameters), dt=dt,
                              tau=_pointer(tau), x1=_pointer(x1),
                              options=ctypes.byref(c_options),
                              iterations=ctypes.byref(iterations))
        if status:
            raise self._step_failed(status, iterations.value)
        return ControlledStep(tau, x1, iterations.value)

    def step_sensitivities(self, x0, u=None, dt: float | None = None, *,
                           options: NewtonOptions | dict | None = None,
                           parameters=None) -> Sensitivities:
        """A step and d s_{k+1}/d s_k, d s_{k+1}/d u_k, d s_{k+1}/d p in s = (phi, omega)
        (implicit function theorem on the converged Newton system; d/dp with s_k held)."""
        dt = step_length(dt, "step_sensitivities")
        if not self.has_sensitivities:
            raise ValueError(f"{self.prefix} was generated without step sensitivities")
        ns, n_p = 2 * self.n, len(self.parameters)
        x1, iterations = np.empty(self.nx), ctypes.c_int(0)
        ds_ds, ds_du, ds_dp = np.empty(ns * ns), np.empty(ns * self.nu), np.empty(ns * n_p)
        c_options = self._fixed_step_options(options, "step_sensitivities")
        status = self._leased("step_sensitivities",
                              x0=_pointer(_vector(x0, self.nx, "x0")),
                              u=self._inputs(u), p=self._p(parameters), dt=dt, x1=_pointer(x1),
                              ds_ds=_pointer(ds_ds), ds_du=_pointer(ds_du),
                              ds_dp=_pointer(ds_dp), options=ctypes.byref(c_options),
                              iterations=ctypes.byref(iterations))
        if status:
            raise self._step_failed(status, iterations.value)
        return Sensitivities(x1, iterations.value, ds_ds.reshape((ns, ns), order="F"),
                             ds_du.reshape((ns, self.nu), order="F"),
                             ds_dp.reshape((ns, n_p), order="F"))

    def simulate(self, phi0, omega0, *, dt: float, n_steps: int, every: int = 1,
                 torques=None, options: NewtonOptions | dict | None = None, scene: str = "",
                 progress=None, parameters=None,
                 stop: StopSignal | None = None, controller=None, hold: int = 1,
                 controller_context=None) -> SimulationResult:
        """Run n_steps steps from joint space (phi0, omega0) in one C call.

        torques: (n_steps, nu) inputs of the actuated joints, row k held over step k (zero if
        None, without allocating them). controller (actuated scenes, instead of torques):
        closes the loop inside the C run, called before every `hold`-th step with the state
        there. Either a Python callable controller(t, phi, omega) -> the nu torques (phi,
        omega: copies, as in a sample row), or a C function of the package's
        <prefix>_controller type (a ctypes function pointer or its address, with
        `controller_context` its context pointer, an int or None), which costs a function
        call a step (the header documents it). An exception raised by a
        Python controller stops the run and propagates. result.torques: the inputs at the
        sampled steps, given or chosen, row j held over step j * every (ceil(n_steps / every)
        rows; with every = 1 every step's, and simulate(..., torques=result.torques) replays
        the run bit for bit).
        progress: called as progress(steps_done) about 20 times a second during the run
        and once at its end (the run's samples do not depend on it). Ctrl-C, or an exception
        raised by progress, stops the run within a step and propagates (KeyboardInterrupt, or
        the exception itself).
        stop: a StopSignal another thread may use to end the run after its current step.
        Raises NewtonError naming the failing step and time; the rows written before it are in
        its `result`.
        """
        try:
            if isinstance(n_steps, bool) or isinstance(every, bool) or isinstance(hold, bool):
                raise TypeError("a bool is no count")
            n_steps, every = operator.index(n_steps), operator.index(every)
            hold = operator.index(hold)
        except TypeError:
            raise ValueError(f"n_steps, every and hold must be integers, got {n_steps!r}, "
                             f"{every!r}, {hold!r}") from None
        if not (0 <= n_steps < 2 ** 63 and 1 <= every < 2 ** 63):
            raise ValueError(f"need 0 <= n_steps and 1 <= every, both below 2^63, got "
                             f"{n_steps}, {every}")
        dt = positive_step(dt)
        check_watchers(progress, stop)
        sampled = -(-n_steps // every)      # the steps 0, every, 2 every, ... before n_steps
        held = sampled if self.nu else 0      # given torques: a copy of their sampled rows
        needed = 8 * ((n_steps // every + 1) * self.nsample + held * self.nu)
        if needed > MAX_SAMPLE_BYTES:
            raise ValueError(f"simulate: {n_steps} steps sampled every {every} would hold "
                             f"{needed / 2 ** 30:.3g} GiB of samples (limit "
                             f"{MAX_SAMPLE_BYTES / 2 ** 30:g} GiB): sample less often (a "
                             "larger every)")
        inputs, recorded, errors, callback = None, None, [], None
        if controller is None and (hold != 1 or controller_context is not None):
            raise ValueError("hold and controller_context go with a controller (were ignored)")
        if controller is not None:
            if not self.nu:
                raise ValueError(f"{self.prefix} has no actuated joints: nothing to control")
            if torques is not None:
                raise ValueError("give torques or a controller, not both")
            if not 1 <= hold < 2 ** 63:
                raise ValueError(f"hold must be an integer >= 1 (steps per controller call), "
                                 f"got {hold!r}")
            recorded = np.zeros((sampled, self.nu))     # C writes the sampled steps' inputs
            address, callback, context = controller_address(controller, self.n, self.nu, errors,
                                                            controller_context)
        elif self.nu and torques is None:      # u = NULL: zero torques, none held per step
            recorded = np.zeros((sampled, self.nu))
        elif self.nu:
            given = real_array(torques, "torques")
            if given.shape != (n_steps, self.nu):
                raise ValueError(f"torques must have shape ({n_steps}, {self.nu}) (steps, "
                                 f"actuated joints), got {given.shape}")
            # A copy: the result's own, whatever the caller does with its array after the run.
            inputs, recorded = _pointer(finite(given, "torques")), given[::every].copy()
        elif torques is not None:
            raise ValueError(f"{self.prefix} has no actuated joints; torques must be None")
        self._p(parameters)    # checks them
        p_values = self.parameter_values(parameters) if self.parameters else np.zeros(0)
        phi0, omega0 = _vector(phi0, self.n, "phi0"), _vector(omega0, self.n, "omega0")
        x0 = self.initial_state(phi0, omega0, p_values)
        rows = self._call("sample_count", n_steps=n_steps, every=every)
        samples = np.zeros((rows, self.nsample))
        stats, control = StatsStruct(), ControlStruct()
        c_options = self.newton_options(options).for_simulate(self.manifest.get("control_law"))
        arguments = dict(x0=_pointer(x0), t0=0.0, dt=dt, n_steps=n_steps, every=every, u=inputs,
                         p=_pointer(p_values) if self.parameters else None,
                         options=ctypes.byref(c_options),
                         samples=_pointer(samples), x_final=None, stats=ctypes.byref(stats),
                         observer=None, context=None, interval=1,
                         control=ctypes.byref(control))
        entry = "simulate_observed"
        if controller is not None:
            entry = "simulate_controlled"
            arguments.update(controller=address, hold=hold, torques=_pointer(recorded),
                             context=context)
        started = time.perf_counter()
        # The run owns this workspace until it returns: a call from a callback meanwhile
        # (progress, the controller) gets another (runtime/workspaces.py).
        arguments["workspace"], home = self._workspaces.lease()
        if stop is not None:
            stop._attach(control)
        try:
            status = run_watched(lambda: self._serve(entry, arguments), control, progress,
                                 f"{self.prefix} simulate")
        finally:
            if stop is not None:
                stop._detach(control)
            self._workspaces.release(arguments["workspace"], home)
        wall = time.perf_counter() - started
        valid = stats.steps // every + 1
        result = SimulationResult(
            scene=scene or self.manifest["scene"], method=self.manifest["method"],
            quadrature=self.manifest["quadrature"], dt=dt, n_steps=int(stats.steps),
            every=every, columns=tuple(self.manifest["sample_columns"]),
            samples=samples[:valid] if status else samples, wall_time=wall,
            newton_iterations=int(stats.newton_iterations),
            max_newton_iterations=int(stats.max_newton_iterations),
            full_newton_fallbacks=int(stats.full_newton_fallbacks),
            split_steps=int(stats.split_steps),
            parameters=dict(zip(self.parameters, map(float, p_values))),
            order=int(self.manifest.get("order", 2)),
            accepted_steps=int(stats.accepted_steps), rejected_steps=int(stats.rejected_steps),
            smallest_dt=float(stats.smallest_dt), largest_dt=float(stats.largest_dt),
            adaptive=bool(c_options.rtol > 0 or c_options.atol > 0),
            rtol=float(c_options.rtol), atol=float(c_options.atol),
            torques=None if recorded is None else recorded[:-(-int(stats.steps) // every)],
            actuated_joints=self.actuated_joints, storage=storage_of(self.manifest))
        if errors:
            raise errors[0]
        if status:
            failed = stats.steps + 1
            raise NewtonError(
                f"step {failed} (t = {stats.steps * dt:.6g} s -> {failed * dt:.6g} s) failed "
                f"after {stats.failed_iterations} Newton iterations: "
                f"{self.status_message(status)}",
                status=status, step=failed, time=stats.steps * dt, result=result)
        return result
