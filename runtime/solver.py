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
}

_double_p = ctypes.POINTER(ctypes.c_double)


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
                ("update_atol", ctypes.c_double), ("residual_tol", ctypes.c_double)]


class _Stats(ctypes.Structure):
    _fields_ = [("steps", ctypes.c_long), ("newton_iterations", ctypes.c_long),
                ("max_newton_iterations", ctypes.c_int), ("failed_iterations", ctypes.c_int)]


@dataclass(frozen=True)
class NewtonOptions:
    """Newton settings of the generated step (see the generated header for their meaning)."""

    max_iterations: int = 20
    update_rtol: float = 1e-10
    update_atol: float = 1e-13
    residual_tol: float = 1e-8

    def _as_c(self) -> _Options:
        return _Options(self.max_iterations, self.update_rtol, self.update_atol,
                        self.residual_tol)


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
        return (len(self.columns) - 3) // 2

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
    def t_realtime(self) -> float:
        """t_computation / t_simulation (model.md section 8)."""
        return self.wall_time / (self.n_steps * self.dt) if self.n_steps else float("nan")

    @property
    def mean_newton_iterations(self) -> float:
        return self.newton_iterations / self.n_steps if self.n_steps else 0.0


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
        self._lib = ctypes.CDLL(str(self.library_path))
        self._declare()
        self._workspace = ctypes.create_string_buffer(self._c("workspace_size")())
        self.default_options = NewtonOptions(**{
            key: type(getattr(NewtonOptions, key))(value)
            for key, value in manifest["newton_defaults"].items()})

    @classmethod
    def from_files(cls, files: dict[str, str], **build_options) -> "Solver":
        manifest = json.loads(files["chaingen.json"])
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
        signatures = {
            "workspace_size": (ctypes.c_size_t, []),
            "initial_state": (i, [dp, dp, dp, vp]),
            "outputs": (i, [dp, dp, dp, dp, dp, vp]),
            "residual": (i, [dp, dp, d, dp, vp]),
            "residual_jacobian": (i, [dp, dp, d, dp, dp, vp]),
            "step": (i, [dp, d, dp, ctypes.POINTER(_Options), vp, ctypes.POINTER(i)]),
            "sample_count": (lng, [lng, lng]),
            "simulate": (i, [dp, d, d, lng, lng, ctypes.POINTER(_Options), vp, dp, dp,
                             ctypes.POINTER(_Stats)]),
        }
        for name, (restype, argtypes) in signatures.items():
            function = self._c(name)
            function.restype = restype
            function.argtypes = argtypes

    def _check(self, status: int, what: str) -> None:
        if status:
            raise NewtonError(f"{self.prefix}_{what}: {STATUS_MESSAGES.get(status, status)}",
                              status=status)

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

    def residual(self, z, x0, dt: float) -> np.ndarray:
        out = np.empty(self.nz)
        self._check(self._c("residual")(_pointer(_vector(z, self.nz, "z")),
                                        _pointer(_vector(x0, self.nx, "x0")), dt,
                                        _pointer(out), self._workspace), "residual")
        return out

    def residual_jacobian(self, z, x0, dt: float) -> tuple[np.ndarray, np.ndarray]:
        residual, jacobian = np.empty(self.nz), np.empty(self.nz * self.nz)
        self._check(self._c("residual_jacobian")(
            _pointer(_vector(z, self.nz, "z")), _pointer(_vector(x0, self.nx, "x0")), dt,
            _pointer(residual), _pointer(jacobian), self._workspace), "residual_jacobian")
        return residual, jacobian.reshape((self.nz, self.nz), order="F")

    def step(self, x0, dt: float, options: NewtonOptions | None = None
             ) -> tuple[np.ndarray, int]:
        """One step: (x1, Newton iterations). Raises NewtonError if Newton fails."""
        x1, iterations = np.empty(self.nx), ctypes.c_int(0)
        c_options = (options or self.default_options)._as_c()
        status = self._c("step")(_pointer(_vector(x0, self.nx, "x0")), dt, _pointer(x1),
                                 ctypes.byref(c_options), self._workspace,
                                 ctypes.byref(iterations))
        if status:
            raise NewtonError(f"step failed after {iterations.value} Newton iterations: "
                              f"{STATUS_MESSAGES.get(status, status)}", status=status)
        return x1, iterations.value

    def simulate(self, phi0, omega0, *, dt: float, n_steps: int, every: int = 1,
                 options: NewtonOptions | None = None, scene: str = "",
                 quadrature: int | None = None) -> SimulationResult:
        """Run n_steps steps from joint space (phi0, omega0) in one C call.

        Raises NewtonError naming the failing step and time; the rows written before it are in
        its `result`.
        """
        if not (0 <= n_steps < 2 ** 63 and 1 <= every < 2 ** 63):
            raise ValueError(f"need 0 <= n_steps and 1 <= every, both below 2^63, got "
                             f"{n_steps}, {every}")
        x0 = self.initial_state(phi0, omega0)
        rows = self._c("sample_count")(n_steps, every)
        samples = np.zeros((rows, self.nsample))
        stats = _Stats()
        c_options = (options or self.default_options)._as_c()
        started = time.perf_counter()
        status = self._c("simulate")(_pointer(x0), 0.0, dt, n_steps, every,
                                     ctypes.byref(c_options), self._workspace,
                                     _pointer(samples), None, ctypes.byref(stats))
        wall = time.perf_counter() - started
        valid = stats.steps // every + 1
        result = SimulationResult(
            scene=scene or self.manifest["scene"], method=self.manifest["method"],
            quadrature=self.manifest["quadrature"], dt=dt, n_steps=int(stats.steps),
            every=every, columns=tuple(self.manifest["sample_columns"]),
            samples=samples[:valid] if status else samples, wall_time=wall,
            newton_iterations=int(stats.newton_iterations),
            max_newton_iterations=int(stats.max_newton_iterations))
        if status:
            failed = stats.steps + 1
            raise NewtonError(
                f"step {failed} (t = {stats.steps * dt:.6g} s -> {failed * dt:.6g} s) failed "
                f"after {stats.failed_iterations} Newton iterations: "
                f"{STATUS_MESSAGES.get(status, status)}",
                status=status, step=failed, time=stats.steps * dt, result=result)
        return result
