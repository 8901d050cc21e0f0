"""Load a built chaingen package and drive it from Python with numpy arrays.

Python calls C once per simulation (`simulate`), not once per step; the per-step entry points
(`step`, `residual_jacobian`, ...) are there for verification and studies. The C signatures are
not written here: they come from the package's manifest, which records the parameter list of
every entry point it exports (chaingen.runtime.contract).
"""
from __future__ import annotations

import ctypes
import json
import time
from pathlib import Path

import numpy as np

from . import contract
from .build import build_shared_library
from .errors import NewtonError
from .interface import NewtonOptions, Observer, StatsStruct, ctypes_type
from .results import Sensitivities, SimulationResult, StepResult

_double_p = ctypes.POINTER(ctypes.c_double)
#: Observer calls per simulate call with a progress callback (at most): a Python call every
#: 1/200 of the run costs nothing measurable.
PROGRESS_CALLS = 200


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(_double_p)


def _vector(values, size: int, name: str) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=np.float64)
    if array.shape != (size,):
        raise ValueError(f"{name} must have {size} entries, got shape {array.shape}")
    return array


class Solver:
    """A loaded package: its manifest (sizes, layouts, entry points) and its C entry points."""

    def __init__(self, library: Path, manifest: dict):
        self.library_path = Path(library)
        self.manifest = manifest
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
        self._lib = ctypes.CDLL(str(self.library_path))
        self._entry_points = {name: self._declare(name, entry)
                              for name, entry in manifest["entry_points"].items()}
        self._workspace = ctypes.create_string_buffer(self._call("workspace_size"))
        self._call("workspace_init", workspace=self._workspace)
        self.default_options = NewtonOptions(**manifest["newton_defaults"])

    @classmethod
    def from_files(cls, files: dict[str, str], **build_options) -> Solver:
        manifest = json.loads(files[contract.MANIFEST])
        build_options.setdefault("source_flags", {
            name: tuple(flags) for name, flags in manifest["source_flags"].items()})
        library = build_shared_library(manifest["prefix"], files, manifest["sources"],
                                       **build_options)
        return cls(library, manifest)

    @classmethod
    def from_directory(cls, directory, **build_options) -> Solver:
        """Build and load the package in `directory`: the files its manifest lists."""
        directory = Path(directory)
        manifest = json.loads((directory / contract.MANIFEST).read_text())
        files = {name: (directory / name).read_text() for name in manifest["files"]}
        return cls.from_files(files, **build_options)

    # -- the C functions ----------------------------------------------------------------------

    def _declare(self, name: str, entry: dict):
        function = getattr(self._lib, f"{self.prefix}_{name}")
        function.restype = ctypes_type(entry["returns"], self.prefix)
        function.argtypes = [ctypes_type(c_type, self.prefix)
                             for _, c_type in entry["parameters"]]
        return function, tuple(parameter for parameter, _ in entry["parameters"])

    def has_entry_point(self, name: str) -> bool:
        return name in self._entry_points

    def _call(self, name: str, **arguments):
        """Call <prefix>_<name> with its arguments by parameter name; arguments for parameters
        the package does not have (u of an unactuated scene, flows) are left out."""
        function, parameters = self._entry_points[name]
        return function(*[arguments[parameter] for parameter in parameters])

    def _check(self, status: int, what: str) -> None:
        if status:
            raise NewtonError(f"{self.prefix}_{what}: {self.status_message(status)}",
                              status=status)

    def status_message(self, status: int) -> str:
        return contract.status_message(status, self.segment_tolerance)

    # -- state maps ---------------------------------------------------------------------------

    def reset(self) -> None:
        """Forget the Newton state carried between steps (warm start, reused Jacobian)."""
        self._call("workspace_init", workspace=self._workspace)

    def initial_state(self, phi, phidot) -> np.ndarray:
        x = np.empty(self.nx)
        self._check(self._call("initial_state", phi=_pointer(_vector(phi, self.n, "phi")),
                               phidot=_pointer(_vector(phidot, self.n, "phidot")),
                               x=_pointer(x), workspace=self._workspace), "initial_state")
        return x

    def outputs(self, x) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(phi, omega, energy, constraint error) of a state."""
        phi, omega, scalars = np.empty(self.n), np.empty(self.n), np.empty(2)
        self._check(self._call("outputs", x=_pointer(_vector(x, self.nx, "x")),
                               phi=_pointer(phi), omega=_pointer(omega),
                               energy=_pointer(scalars[:1]),
                               constraint_error=_pointer(scalars[1:]),
                               workspace=self._workspace), "outputs")
        return phi, omega, float(scalars[0]), float(scalars[1])

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

    def residual(self, z, x0, dt: float, u=None) -> np.ndarray:
        out = np.empty(self.nz)
        self._check(self._call("residual", z=_pointer(_vector(z, self.nz, "z")),
                               x0=_pointer(_vector(x0, self.nx, "x0")), u=self._inputs(u),
                               dt=dt, residual=_pointer(out), workspace=self._workspace),
                    "residual")
        return out

    def residual_jacobian(self, z, x0, dt: float, u=None) -> tuple[np.ndarray, np.ndarray]:
        residual, jacobian = np.empty(self.nz), np.empty(self.nz * self.nz)
        self._check(self._call("residual_jacobian", z=_pointer(_vector(z, self.nz, "z")),
                               x0=_pointer(_vector(x0, self.nx, "x0")), u=self._inputs(u),
                               dt=dt, residual=_pointer(residual), jacobian=_pointer(jacobian),
                               workspace=self._workspace), "residual_jacobian")
        return residual, jacobian.reshape((self.nz, self.nz), order="F")

    def holding_torques(self, phi) -> np.ndarray:
        """dV/dphi: the joint torques that hold the chain still at phi (actuated scenes)."""
        if not self.has_entry_point("holding_torques"):
            raise ValueError(f"{self.prefix} has no actuated joints: no holding_torques")
        tau = np.empty(self.n)
        self._check(self._call("holding_torques", phi=_pointer(_vector(phi, self.n, "phi")),
                               tau=_pointer(tau), workspace=self._workspace), "holding_torques")
        return tau

    # -- steps --------------------------------------------------------------------------------

    def _step_failed(self, status: int, iterations: int) -> NewtonError:
        return NewtonError(f"step failed after {iterations} Newton iterations: "
                           f"{self.status_message(status)}", status=status)

    def step(self, x0, dt: float, u=None, options: NewtonOptions | None = None) -> StepResult:
        """One step from x0 with inputs u (actuated scenes). Raises NewtonError if it fails."""
        x1, iterations, flows = np.empty(self.nx), ctypes.c_int(0), np.zeros(2)
        c_options = (options or self.default_options).as_c()
        status = self._call("step", x0=_pointer(_vector(x0, self.nx, "x0")), u=self._inputs(u),
                            dt=dt, x1=_pointer(x1), flows=_pointer(flows),
                            options=ctypes.byref(c_options), workspace=self._workspace,
                            iterations=ctypes.byref(iterations))
        if status:
            raise self._step_failed(status, iterations.value)
        return StepResult(x1, iterations.value, float(flows[0]), float(flows[1]))

    def step_sensitivities(self, x0, dt: float, u=None,
                           options: NewtonOptions | None = None) -> Sensitivities:
        """A step and d s_{k+1}/d s_k, d s_{k+1}/d u_k in s = (phi, omega) (implicit function
        theorem on the converged Newton system)."""
        if not self.has_sensitivities:
            raise ValueError(f"{self.prefix} was generated without step sensitivities")
        ns = 2 * self.n
        x1, iterations = np.empty(self.nx), ctypes.c_int(0)
        ds_ds, ds_du = np.empty(ns * ns), np.empty(ns * self.nu)
        c_options = (options or self.default_options).as_c()
        status = self._call("step_sensitivities", x0=_pointer(_vector(x0, self.nx, "x0")),
                            u=self._inputs(u), dt=dt, x1=_pointer(x1), ds_ds=_pointer(ds_ds),
                            ds_du=_pointer(ds_du), options=ctypes.byref(c_options),
                            workspace=self._workspace, iterations=ctypes.byref(iterations))
        if status:
            raise self._step_failed(status, iterations.value)
        return Sensitivities(x1, iterations.value, ds_ds.reshape((ns, ns), order="F"),
                             ds_du.reshape((ns, self.nu), order="F"))

    def simulate(self, phi0, omega0, *, dt: float, n_steps: int, every: int = 1,
                 torques=None, options: NewtonOptions | None = None, scene: str = "",
                 quadrature: int | None = None, progress=None) -> SimulationResult:
        """Run n_steps steps from joint space (phi0, omega0) in one C call.

        torques: (n_steps, nu) inputs of the actuated joints, row k held over step k (zero if
        None). progress: called as progress(steps_done) about 200 times during the run (the
        run's samples do not depend on it); Ctrl-C in it stops the run and raises
        KeyboardInterrupt. Raises NewtonError naming the failing step and time; the rows
        written before it are in its `result`.
        """
        if not (0 <= n_steps < 2 ** 63 and 1 <= every < 2 ** 63):
            raise ValueError(f"need 0 <= n_steps and 1 <= every, both below 2^63, got "
                             f"{n_steps}, {every}")
        inputs = None
        if self.nu:
            u = (np.zeros((n_steps, self.nu)) if torques is None
                 else np.ascontiguousarray(torques, dtype=np.float64))
            if u.shape != (n_steps, self.nu):
                raise ValueError(f"torques must have shape ({n_steps}, {self.nu}) (steps, "
                                 f"actuated joints), got {u.shape}")
            inputs = _pointer(u)
        elif torques is not None:
            raise ValueError(f"{self.prefix} has no actuated joints; torques must be None")
        x0 = self.initial_state(phi0, omega0)
        rows = self._call("sample_count", n_steps=n_steps, every=every)
        samples = np.zeros((rows, self.nsample))
        stats = StatsStruct()
        c_options = (options or self.default_options).as_c()
        arguments = dict(x0=_pointer(x0), t0=0.0, dt=dt, n_steps=n_steps, every=every, u=inputs,
                         options=ctypes.byref(c_options), workspace=self._workspace,
                         samples=_pointer(samples), x_final=None, stats=ctypes.byref(stats))
        interrupted = []
        started = time.perf_counter()
        if progress is not None:
            def observe(steps, _context):
                try:
                    progress(int(steps))
                except KeyboardInterrupt:
                    interrupted.append(True)
                    return 1
                return 0
            status = self._call("simulate_observed", **arguments, observer=Observer(observe),
                                context=None, interval=max(1, n_steps // PROGRESS_CALLS))
        else:
            status = self._call("simulate", **arguments)
        wall = time.perf_counter() - started
        valid = stats.steps // every + 1
        result = SimulationResult(
            scene=scene or self.manifest["scene"], method=self.manifest["method"],
            quadrature=self.manifest["quadrature"], dt=dt, n_steps=int(stats.steps),
            every=every, columns=tuple(self.manifest["sample_columns"]),
            samples=samples[:valid] if status else samples, wall_time=wall,
            newton_iterations=int(stats.newton_iterations),
            max_newton_iterations=int(stats.max_newton_iterations))
        if interrupted:
            raise KeyboardInterrupt(f"simulation interrupted after {stats.steps} steps")
        if status:
            failed = stats.steps + 1
            raise NewtonError(
                f"step {failed} (t = {stats.steps * dt:.6g} s -> {failed * dt:.6g} s) failed "
                f"after {stats.failed_iterations} Newton iterations: "
                f"{self.status_message(status)}",
                status=status, step=failed, time=stats.steps * dt, result=result)
        return result
