"""Load a built chaingen package and drive it from Python with numpy arrays.

Python calls C once per simulation (`simulate`), not once per step; the per-step entry points
(`step`, `residual_jacobian`, ...) are there for verification and studies.
"""
from __future__ import annotations

import ctypes
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .build import build_shared_library

#: Status codes of the generated C (the header's PREFIX_OK, ...).
STATUS_MESSAGES = {
    1: "Newton's method did not converge within max_iterations",
    2: "the Newton Jacobian is singular (no usable pivot)",
    3: "NaN or Inf in the residual or the Newton iterate",
    4: "bad argument",
    5: "a generated function reported an evaluation error",
    7: "interrupted by the observer of the run",
    6: "a spring segment came within 1e-6 of the geometry's size of zero length or passed "
       "through it (turned by 90 degrees or more in one step), where its direction is "
       "undefined (model.md 2)",
}

_double_p = ctypes.POINTER(ctypes.c_double)
#: <prefix>_observer: int (*)(long steps, void *context).
_OBSERVER = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_long, ctypes.c_void_p)
#: Observer calls per simulate call with a progress callback (at most): a Python call every
#: 1/200 of the run costs nothing measurable.
PROGRESS_CALLS = 200


class NewtonError(RuntimeError):
    """A step failed; carries where and why, and the samples written before the failure."""

    def __init__(self, message: str, *, status: int, step: int | None = None,
                 time: float | None = None, result: "SimulationResult | None" = None):
        super().__init__(message)
        self.status = status
        self.step = step
        self.time = time
        self.result = result


class _Options(ctypes.Structure):
    _fields_ = [("max_iterations", ctypes.c_int), ("update_rtol", ctypes.c_double),
                ("update_atol", ctypes.c_double), ("residual_tol", ctypes.c_double),
                ("warm_start", ctypes.c_int), ("reuse_jacobian", ctypes.c_int)]


class _Stats(ctypes.Structure):
    _fields_ = [("steps", ctypes.c_long), ("newton_iterations", ctypes.c_long),
                ("max_newton_iterations", ctypes.c_int), ("failed_iterations", ctypes.c_int)]


#: NewtonOptions.reuse_jacobian: when dF/dz is evaluated (the header's <PREFIX>_JACOBIAN_*).
JACOBIAN_EVERY_ITERATE = 0  # full Newton
JACOBIAN_ACROSS_STEPS = 1   # simplified Newton: kept over iterations and steps
JACOBIAN_PER_STEP = 2       # Newton-chord: at each step's first iterate, kept within the step
_JACOBIAN_MODES = (JACOBIAN_EVERY_ITERATE, JACOBIAN_ACROSS_STEPS, JACOBIAN_PER_STEP)


@dataclass(frozen=True)
class NewtonOptions:
    """Newton settings of the generated step (see the generated header for their meaning).
    The defaults here are full Newton; a Solver's `default_options` are its package's."""

    max_iterations: int = 20
    update_rtol: float = 1e-10
    update_atol: float = 1e-13
    residual_tol: float = 1e-8
    warm_start: bool = True       # continue from the previous step's solutions (chained steps)
    reuse_jacobian: int = JACOBIAN_EVERY_ITERATE  # one of the JACOBIAN_* modes above

    def __post_init__(self):
        if self.reuse_jacobian not in _JACOBIAN_MODES:
            raise ValueError(f"NewtonOptions.reuse_jacobian: must be one of {_JACOBIAN_MODES} "
                             f"(every iterate, across steps, per step), got {self.reuse_jacobian!r}")

    def _as_c(self) -> _Options:
        return _Options(self.max_iterations, self.update_rtol, self.update_atol,
                        self.residual_tol, int(self.warm_start), int(self.reuse_jacobian))


@dataclass(frozen=True)
class SimulationResult:
    """Samples of one simulation: rows of the trajectory file's columns, and its counters."""

    scene: str
    method: str
    quadrature: int | None
    dt: float
    n_steps: int
    every: int
    columns: tuple[str, ...]
    samples: np.ndarray = field(repr=False)
    wall_time: float            # seconds spent in the C loop
    newton_iterations: int      # total over all steps
    max_newton_iterations: int

    def column(self, name: str) -> np.ndarray:
        return self.samples[:, self.columns.index(name)]

    @property
    def n_joints(self) -> int:
        return sum(1 for name in self.columns if name.startswith("phi"))

    @property
    def t(self) -> np.ndarray:
        return self.samples[:, 0]

    @property
    def phi(self) -> np.ndarray:
        return self.samples[:, 1:1 + self.n_joints]

    @property
    def omega(self) -> np.ndarray:
        return self.samples[:, 1 + self.n_joints:1 + 2 * self.n_joints]

    @property
    def energy(self) -> np.ndarray:
        return self.column("energy")

    @property
    def energy_error(self) -> np.ndarray:
        """e_E = H - H_0 (model.md section 8)."""
        return self.energy - self.energy[0]

    @property
    def constraint_error(self) -> np.ndarray:
        return self.column("constraint_error")

    @property
    def input_work(self) -> np.ndarray:
        """Work of the joint torques since t = 0 (zero for a scene without energy flows)."""
        return self.column("input_work") if "input_work" in self.columns else 0 * self.t

    @property
    def dissipated(self) -> np.ndarray:
        """Energy dissipated by joint damping since t = 0 (zero for a scene without)."""
        return self.column("dissipated") if "dissipated" in self.columns else 0 * self.t

    @property
    def balance_error(self) -> np.ndarray:
        """H - H_0 - input_work + dissipated: the energy the scheme created (model.md 7)."""
        return self.energy_error - self.input_work + self.dissipated

    @property
    def t_realtime(self) -> float:
        """t_computation / t_simulation (model.md section 8)."""
        return self.wall_time / (self.n_steps * self.dt) if self.n_steps else float("nan")

    @property
    def mean_newton_iterations(self) -> float:
        return self.newton_iterations / self.n_steps if self.n_steps else 0.0


@dataclass(frozen=True)
class StepResult:
    """One step: the next state, the Newton iterations spent, and the step's energy flows."""

    x1: np.ndarray
    iterations: int
    input_work: float = 0.0   # work of the joint torques over the step (J)
    dissipated: float = 0.0   # energy dissipated by joint damping over the step (J), >= 0


@dataclass(frozen=True)
class Sensitivities:
    """A step and its Jacobians in the joint-space state s = (phi, omega)."""

    x1: np.ndarray
    iterations: int
    ds_ds: np.ndarray   # (2n, 2n): d s_{k+1} / d s_k
    ds_du: np.ndarray   # (2n, nu): d s_{k+1} / d u_k


def _pointer(array: np.ndarray):
    return array.ctypes.data_as(_double_p)


def _vector(values, size: int, name: str) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=np.float64)
    if array.shape != (size,):
        raise ValueError(f"{name} must have {size} entries, got shape {array.shape}")
    return array


class Solver:
    """A loaded package: its manifest (sizes, layouts) and its C entry points."""

    def __init__(self, library: Path, manifest: dict):
        self.library_path = Path(library)
        self.manifest = manifest
        self.prefix = manifest["prefix"]
        self.n = manifest["n_joints"]
        self.nx = manifest["nx"]
        self.nz = manifest["nz"]
        self.nsample = manifest["nsample"]
        self.actuated_joints = tuple(manifest.get("actuated_joints", ()))
        self.nu = len(self.actuated_joints)
        self.energy_flows = bool(manifest.get("energy_flows", False))
        self.has_sensitivities = bool(manifest.get("sensitivities", False))
        self._lib = ctypes.CDLL(str(self.library_path))
        self._declare()
        self._workspace = ctypes.create_string_buffer(self._c("workspace_size")())
        self._c("workspace_init")(self._workspace)
        self.default_options = NewtonOptions(**{
            key: type(getattr(NewtonOptions, key))(value)
            for key, value in manifest["newton_defaults"].items()})

    @classmethod
    def from_files(cls, files: dict[str, str], **build_options) -> "Solver":
        manifest = json.loads(files["chaingen.json"])
        build_options.setdefault("source_flags", {
            name: tuple(flags) for name, flags in manifest.get("source_flags", {}).items()})
        library = build_shared_library(manifest["prefix"], files, manifest["sources"],
                                       **build_options)
        return cls(library, manifest)

    @classmethod
    def from_directory(cls, directory, **build_options) -> "Solver":
        directory = Path(directory)
        files = {path.name: path.read_text() for path in sorted(directory.iterdir())
                 if path.is_file()}
        return cls.from_files(files, **build_options)

    def _c(self, name: str):
        return getattr(self._lib, f"{self.prefix}_{name}")

    def _declare(self) -> None:
        vp, dp, d, i, lng = ctypes.c_void_p, _double_p, ctypes.c_double, ctypes.c_int, ctypes.c_long
        options, stats, count = ctypes.POINTER(_Options), ctypes.POINTER(_Stats), ctypes.POINTER(i)
        u = [dp] if self.nu else []          # the input path exists only for actuated scenes
        flows = [dp] if self.energy_flows else []
        signatures = {
            "workspace_size": (ctypes.c_size_t, []),
            "workspace_init": (None, [ctypes.c_void_p]),
            "initial_state": (i, [dp, dp, dp, vp]),
            "outputs": (i, [dp, dp, dp, dp, dp, vp]),
            "residual": (i, [dp, dp, *u, d, dp, vp]),
            "residual_jacobian": (i, [dp, dp, *u, d, dp, dp, vp]),
            "step": (i, [dp, *u, d, dp, *flows, options, vp, count]),
            "sample_count": (lng, [lng, lng]),
            "simulate": (i, [dp, d, d, lng, lng, *u, options, vp, dp, dp, stats]),
        }
        self._observable = hasattr(self._lib, f"{self.prefix}_simulate_observed")
        if self._observable:   # packages generated before simulate_observed existed lack it
            signatures["simulate_observed"] = (
                i, [dp, d, d, lng, lng, *u, options, vp, dp, dp, stats, _OBSERVER, vp, lng])
        if self.nu:
            signatures["holding_torques"] = (i, [dp, dp, vp])
        if self.has_sensitivities:
            signatures["step_sensitivities"] = (i, [dp, *u, d, dp, dp, *u, options, vp, count])
        for name, (restype, argtypes) in signatures.items():
            function = self._c(name)
            function.restype = restype
            function.argtypes = argtypes

    def _check(self, status: int, what: str) -> None:
        if status:
            raise NewtonError(f"{self.prefix}_{what}: {STATUS_MESSAGES.get(status, status)}",
                              status=status)

    def reset(self) -> None:
        """Forget the Newton state carried between steps (warm start, reused Jacobian)."""
        self._c("workspace_init")(self._workspace)

    def initial_state(self, phi, phidot) -> np.ndarray:
        x = np.empty(self.nx)
        self._check(self._c("initial_state")(_pointer(_vector(phi, self.n, "phi")),
                                             _pointer(_vector(phidot, self.n, "phidot")),
                                             _pointer(x), self._workspace), "initial_state")
        return x

    def outputs(self, x) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(phi, omega, energy, constraint error) of a state."""
        phi, omega, scalars = np.empty(self.n), np.empty(self.n), np.empty(2)
        self._check(self._c("outputs")(_pointer(_vector(x, self.nx, "x")), _pointer(phi),
                                       _pointer(omega), _pointer(scalars[:1]),
                                       _pointer(scalars[1:]), self._workspace), "outputs")
        return phi, omega, float(scalars[0]), float(scalars[1])

    def _inputs(self, u) -> list:
        """The u argument of a step function: [pointer] for an actuated scene, else []."""
        if not self.nu:
            if u is not None and np.size(u):
                raise ValueError(f"{self.prefix} has no actuated joints; u must be None")
            return []
        if u is None:
            u = np.zeros(self.nu)
        return [_pointer(_vector(u, self.nu, "u"))]

    def residual(self, z, x0, dt: float, u=None) -> np.ndarray:
        out = np.empty(self.nz)
        self._check(self._c("residual")(_pointer(_vector(z, self.nz, "z")),
                                        _pointer(_vector(x0, self.nx, "x0")), *self._inputs(u),
                                        dt, _pointer(out), self._workspace), "residual")
        return out

    def residual_jacobian(self, z, x0, dt: float, u=None) -> tuple[np.ndarray, np.ndarray]:
        residual, jacobian = np.empty(self.nz), np.empty(self.nz * self.nz)
        self._check(self._c("residual_jacobian")(
            _pointer(_vector(z, self.nz, "z")), _pointer(_vector(x0, self.nx, "x0")),
            *self._inputs(u), dt, _pointer(residual), _pointer(jacobian), self._workspace),
            "residual_jacobian")
        return residual, jacobian.reshape((self.nz, self.nz), order="F")

    def holding_torques(self, phi) -> np.ndarray:
        """dV/dphi: the joint torques that hold the chain still at phi (actuated scenes)."""
        if not self.nu:
            raise ValueError(f"{self.prefix} has no actuated joints: no holding_torques")
        tau = np.empty(self.n)
        self._check(self._c("holding_torques")(_pointer(_vector(phi, self.n, "phi")),
                                               _pointer(tau), self._workspace), "holding_torques")
        return tau

    def _step_failed(self, status: int, iterations: int) -> NewtonError:
        return NewtonError(f"step failed after {iterations} Newton iterations: "
                           f"{STATUS_MESSAGES.get(status, status)}", status=status)

    def step(self, x0, dt: float, u=None, options: NewtonOptions | None = None) -> StepResult:
        """One step from x0 with inputs u (actuated scenes). Raises NewtonError if it fails."""
        x1, iterations, flows = np.empty(self.nx), ctypes.c_int(0), np.zeros(2)
        c_options = (options or self.default_options)._as_c()
        status = self._c("step")(_pointer(_vector(x0, self.nx, "x0")), *self._inputs(u), dt,
                                 _pointer(x1), *([_pointer(flows)] if self.energy_flows else []),
                                 ctypes.byref(c_options), self._workspace,
                                 ctypes.byref(iterations))
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
        c_options = (options or self.default_options)._as_c()
        status = self._c("step_sensitivities")(
            _pointer(_vector(x0, self.nx, "x0")), *self._inputs(u), dt, _pointer(x1),
            _pointer(ds_ds), *([_pointer(ds_du)] if self.nu else []), ctypes.byref(c_options),
            self._workspace, ctypes.byref(iterations))
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
        inputs = []
        if self.nu:
            u = (np.zeros((n_steps, self.nu)) if torques is None
                 else np.ascontiguousarray(torques, dtype=np.float64))
            if u.shape != (n_steps, self.nu):
                raise ValueError(f"torques must have shape ({n_steps}, {self.nu}) (steps, "
                                 f"actuated joints), got {u.shape}")
            inputs = [_pointer(u)]
        elif torques is not None:
            raise ValueError(f"{self.prefix} has no actuated joints; torques must be None")
        x0 = self.initial_state(phi0, omega0)
        rows = self._c("sample_count")(n_steps, every)
        samples = np.zeros((rows, self.nsample))
        stats = _Stats()
        c_options = (options or self.default_options)._as_c()
        arguments = [_pointer(x0), 0.0, dt, n_steps, every, *inputs, ctypes.byref(c_options),
                     self._workspace, _pointer(samples), None, ctypes.byref(stats)]
        interrupted = []
        started = time.perf_counter()
        if progress is not None and self._observable:
            def observe(steps, _context):
                try:
                    progress(int(steps))
                except KeyboardInterrupt:
                    interrupted.append(True)
                    return 1
                return 0
            observer = _OBSERVER(observe)
            interval = max(1, n_steps // PROGRESS_CALLS)
            status = self._c("simulate_observed")(*arguments, observer, None, interval)
        else:
            status = self._c("simulate")(*arguments)
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
                f"{STATUS_MESSAGES.get(status, status)}",
                status=status, step=failed, time=stats.steps * dt, result=result)
        return result
