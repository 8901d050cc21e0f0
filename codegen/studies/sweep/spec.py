"""The sweep spec (docs/sweep-format.md): which scene, which numbers vary, how, and what to keep.

    scene = "three_link_mono.toml"       # relative to the spec file
    method = "es"                        # optional, else the scene's
    mode = "product"                     # product | zip | sample
    [axes]
    "springs[0].stiffness" = [5.0, 10.0, 20.0]
    "links[1].mass" = { from = 0.5, to = 2.0, num = 16 }

As strict as a scene file: an unknown key, a path that names no number of the scene, a value
out of the scene's own range (checked for every run's value), zip axes of unequal length, a
t_end that is not a whole number of steps of dt: each a one-line SweepError naming the key,
before anything runs or is written.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ChaingenError, SceneError
from ...runtime.contract import ADAPTIVE_TOLERANCES
from ...scene import Scene, SolverSpec
from ...scene.parameters import NumberPath
from ...scene.solver_rules import REQUEST_KEYS, request_refusal
from ...scene.solver_spec import control_refusal, numbers_of
from ...simulation import MAX_SAMPLE_BYTES, MAX_STEPS
from ...spatial.reader import load_either_scene
from ...spatial.values import SpatialScene
from .checks import check_runs

MODES = ("product", "zip", "sample")
SAMPLERS = ("sobol", "latin-hypercube")
SPACINGS = ("linear", "log")
TOP_KEYS = ("scene", "method", "quadrature", "order", "rtol", "atol", "mode", "samples",
            "sampler", "seed", "t_end", "every", "axes")
RANGE_KEYS = ("from", "to", "num", "spacing")
#: A sweep of more runs than this is refused as a mistake (a product of long axes).
MAX_RUNS = 10_000_000
#: Chunks of about this fraction of the runs (at most MAX_CHUNK): small enough to spread
#: over the workers and to lose little when interrupted, big enough that a chunk's overhead
#: (a task, a file) is small against its runs. Fixed by the run count alone, so a rerun on
#: another machine continues the same store.
CHUNKS = 40
MAX_CHUNK = 64
#: The trajectories of all runs (trajectories.zarr, uncompressed) may take at most this much.
MAX_TRAJECTORY_BYTES = 2 ** 40


def chunk_size(runs: int) -> int:
    return max(1, min(MAX_CHUNK, math.ceil(runs / CHUNKS)))


class SweepError(ChaingenError):
    """A sweep spec that cannot be run; the message names the spec file and the key."""


@dataclass(frozen=True)
class Axis:
    """One varied number: its path in the scene, and its values (product, zip) or range
    (sample)."""

    number: NumberPath
    values: tuple[float, ...] = ()
    low: float | None = None
    high: float | None = None
    spacing: str = "linear"
    num: int = 0                  # a range of product or zip mode: its count (values not made)

    @property
    def path(self) -> str:
        return self.number.path

    @property
    def size(self) -> int:
        """The axis's count of values, known before any is made."""
        return self.num or len(self.values)

    def grid(self) -> np.ndarray:
        """The axis's values (a range's made now, after the run count is checked)."""
        if not self.num:
            return np.array(self.values, dtype=np.float64)
        if self.spacing == "log":
            return np.geomspace(self.low, self.high, self.num)
        return np.linspace(self.low, self.high, self.num)


class Runs(Sequence):
    """Every run's values, held as one column per axis (numpy, float64): run k is
    {path: column[k]}. Compact for 10^7 runs, where a dict per run would take gigabytes."""

    def __init__(self, columns: dict[str, np.ndarray]):
        self.columns = {path: np.ascontiguousarray(values, dtype=np.float64)
                        for path, values in columns.items()}
        self._count = len(next(iter(self.columns.values()))) if self.columns else 0

    def __len__(self) -> int:
        return self._count

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[k] for k in range(*index.indices(self._count))]
        if not -self._count <= index < self._count:
            raise IndexError(f"run {index} of {self._count}")
        return {path: float(column[index]) for path, column in self.columns.items()}

    def column(self, path: str) -> np.ndarray:
        return self.columns[path]

    def __eq__(self, other) -> bool:
        if not isinstance(other, Runs):
            return NotImplemented
        return (list(self.columns) == list(other.columns)
                and all(np.array_equal(self.columns[path], other.columns[path])
                        for path in self.columns))

    __hash__ = None

    def __repr__(self) -> str:
        return f"Runs({self._count} runs of {', '.join(self.columns)})"


@dataclass(frozen=True)
class SweepSpec:
    """A checked spec: the base scene, the scheme, the axes, and every run's values."""

    source: str
    scene_path: Path
    scene: Scene | SpatialScene
    method: str
    quadrature: int
    mode: str
    axes: tuple[Axis, ...]
    runs: Runs = field(repr=False)
    t_end: float
    every: int
    seed: int
    sampler: str
    document: dict = field(repr=False)
    scene_text: str = field(repr=False, default="")
    order: int = 2                # of the step (docs/model.md, section 14)
    rtol: float = 0.0             # adaptive steps' tolerances (both 0: fixed steps of dt)
    atol: float = 0.0

    @property
    def options(self) -> dict | None:
        """The Newton options of every run: the adaptive tolerances, if any."""
        if not (self.rtol or self.atol):
            return None
        return {"rtol": self.rtol, "atol": self.atol}

    @property
    def parameters(self) -> tuple[str, ...]:
        """The varied numbers compiled into the solver, which it takes as parameters."""
        return tuple(axis.path for axis in self.axes if axis.number.compiled)

    @property
    def solver(self) -> SolverSpec:
        """The request of the sweep's one solver: the spec's scheme, its varied numbers as
        run-time parameters, no step sensitivities, es's discrete gradient the base scene's
        (simulation.gradient)."""
        return SolverSpec(self.scene, self.method, self.quadrature, order=self.order,
                          parameters=self.parameters, sensitivities=False,
                          gradient=self.scene.simulation.gradient)

    @functools.cached_property
    def digest(self) -> str:
        """What identifies the sweep's results: the expanded spec and the base scene (as read
        when the spec was checked, so a worker elsewhere needs no scene file)."""
        text = json.dumps({"document": self.document, "scene": self.scene_text},
                          sort_keys=True, default=str)
        digest = hashlib.sha256(text.encode())
        for path, column in self.runs.columns.items():
            digest.update(path.encode() + b"\0" + column.astype("<f8").tobytes())
        return digest.hexdigest()

    @functools.cached_property
    def steps(self) -> np.ndarray:
        """Every run's step count (int64), as n_steps gives it (checked: at most MAX_STEPS)."""
        return _step_counts(self.runs, self.scene.simulation.dt, self.t_end)

    @property
    def chunk(self) -> int:
        return chunk_size(len(self.runs))

    def n_steps(self, run: dict[str, float]) -> int:
        dt = run.get("simulation.dt", self.scene.simulation.dt)
        t_end = run.get("simulation.t_end", self.t_end)
        return max(1, round(t_end / dt))

    def sample_count(self) -> int:
        """Trajectory samples kept per run: the longest run's (0 without trajectories)."""
        if not self.every:
            return 0
        return int(self.steps.max()) // self.every + 1


def _step_counts(runs: Runs, dt: float, t_end: float) -> np.ndarray:
    dts = runs.columns.get("simulation.dt", np.array([dt]))
    ends = runs.columns.get("simulation.t_end", np.array([t_end]))
    with np.errstate(all="ignore"):
        counts = np.maximum(np.rint(ends / dts), 1.0)
    counts = np.broadcast_to(np.minimum(counts, 2.0 ** 62), (len(runs),))
    return counts.astype(np.int64)


def load_spec(path: str | os.PathLike) -> SweepSpec:
    """Read and check the spec file at `path`; SweepError names what is wrong."""
    source = os.fspath(path)
    try:
        document = tomllib.loads(Path(source).read_text(encoding="utf-8"))
    except OSError as error:
        raise SweepError(f"{source}: cannot read sweep spec: {error.strerror or error}") from None
    except UnicodeDecodeError:
        raise SweepError(f"{source}: the file is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as error:
        raise SweepError(f"{source}: TOML syntax error: {error}") from None
    except RecursionError:
        raise SweepError(f"{source}: TOML nested too deeply") from None
    return parse_spec(document, source, base=Path(source).parent)


def parse_spec(document: dict[str, Any], source: str = "<sweep>", *,
               base: Path = Path(".")) -> SweepSpec:
    """Check a spec document (a dict, as TOML or Python gives it; numpy's scalars and arrays
    read as the numbers and lists they hold)."""
    def fail(key: str, what: str) -> SweepError:
        return SweepError(f"{source}: {key}: {what}")

    if not isinstance(document, dict):
        raise SweepError(f"{source}: a sweep spec is a table of keys (a dict), "
                         f"got {type(document).__name__}")
    document = _plain(document)
    for key in document:
        if key not in TOP_KEYS:
            raise fail(key, f"unknown key (allowed: {', '.join(TOP_KEYS)})")
    if "scene" not in document or not isinstance(document["scene"], str):
        raise fail("scene", "missing: the scene file (a string, relative to the spec file)")
    scene_path = (base / document["scene"]).resolve() if not Path(
        document["scene"]).is_absolute() else Path(document["scene"])
    try:
        scene = load_either_scene(scene_path)
    except SceneError as error:
        raise SweepError(f"{source}: scene: {error}") from None
    request = {key: document.get(key, getattr(scene.simulation, key)) for key in REQUEST_KEYS}
    refused = request_refusal(request)
    if refused:
        raise fail(refused.key, refused.message)
    refused = control_refusal(scene, request["method"], request["order"],
                              *(float(request[name]) for name in ADAPTIVE_TOLERANCES))
    if refused:    # named where the value came from: this spec, or the scene's [simulation]
        raise fail(refused.key if refused.key in document
                   else f"scene: {scene_path}: simulation.{refused.key}", refused.message)
    method, quadrature, order = request["method"], request["quadrature"], request["order"]
    tolerances = {name: float(request[name]) for name in ADAPTIVE_TOLERANCES}
    mode = document.get("mode", "product")
    if mode not in MODES:
        raise fail("mode", f"must be one of {', '.join(MODES)}, got {mode!r}")
    sampler = document.get("sampler", "sobol")
    if sampler not in SAMPLERS:
        raise fail("sampler", f"must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    seed = document.get("seed", 0)
    if not (_integer(seed) and seed >= 0):
        raise fail("seed", f"must be an integer >= 0, got {seed!r}")
    samples = document.get("samples")
    if mode == "sample":
        if not (_integer(samples) and 1 <= samples <= MAX_RUNS):
            raise fail("samples", f"must be an integer from 1 to {MAX_RUNS} with mode = "
                                  f"\"sample\", got {samples!r}")
    elif samples is not None:
        raise fail("samples", f"only with mode = \"sample\" (this sweep's mode is {mode!r})")
    t_end = document.get("t_end", scene.simulation.t_end)
    if not (_number(t_end) and math.isfinite(t_end) and t_end > 0):
        raise fail("t_end", f"must be > 0 and finite (s), got {t_end!r}")
    every = document.get("every", 0)
    if not (_integer(every) and every >= 0):
        raise fail("every", f"must be an integer >= 0 (0: summaries only), got {every!r}")
    axes_table = document.get("axes")
    if not isinstance(axes_table, dict) or not axes_table:
        raise fail("axes", "missing: at least one varied number, e.g. "
                           "[axes] \"springs[0].stiffness\" = [5.0, 10.0]")
    axes = tuple(_axis(scene, path, value, mode, source) for path, value in axes_table.items())
    named: dict[str, str] = {}
    for key, axis in zip(axes_table, axes):
        if axis.path in named:
            raise fail(f"axes.{json.dumps(key)}", f"names the same number as "
                                                  f"axes.{json.dumps(named[axis.path])} "
                                                  f"({axis.path}); give each number once")
        named[axis.path] = key
    if mode == "zip":
        lengths = {axis.path: axis.size for axis in axes}
        if len(set(lengths.values())) > 1:
            raise fail("axes", "zip axes must have equal lengths, got "
                               + ", ".join(f"{path}: {count}" for path, count in lengths.items()))
    runs = _expand(axes, mode, samples, sampler, seed, source)
    spec = SweepSpec(source=source, scene_path=scene_path, scene=scene, method=method,
                     quadrature=quadrature, mode=mode, axes=axes, runs=runs,
                     t_end=float(t_end), every=every, seed=seed, sampler=sampler,
                     document=document, scene_text=scene_path.read_text(encoding="utf-8"),
                     order=order, **tolerances)
    _check_values(spec)
    _check_sizes(spec)
    return spec


def _plain(value):
    """`value` in Python's own types: numpy scalars as the int, float or bool they hold, arrays
    and tuples as lists, so that a spec built with numpy reads (and digests) as its TOML would."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return value.item() if isinstance(value, np.generic) else value


def _integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _axis(scene: Scene | SpatialScene, path: str, value, mode: str, source: str) -> Axis:
    where = f"axes.{json.dumps(path)}"
    try:
        number = numbers_of(scene).number_path(scene, path)
    except SceneError as error:
        raise SweepError(f"{source}: {where}: {str(error).split(': ', 1)[1]}") from None
    if isinstance(value, list):
        if mode == "sample":
            raise SweepError(f"{source}: {where}: mode = \"sample\" draws from a range: give "
                             "{ from = ..., to = ... }, not a list")
        if not value or not all(_number(item) and math.isfinite(item) for item in value):
            raise SweepError(f"{source}: {where}: must be a non-empty list of finite numbers, "
                             f"got {value!r}")
        return Axis(number, values=tuple(float(item) for item in value))
    if not isinstance(value, dict):
        raise SweepError(f"{source}: {where}: must be a list of values or a range "
                         f"{{ from = ..., to = ..., num = ... }}, got {value!r}")
    for key in value:
        if key not in RANGE_KEYS:
            raise SweepError(f"{source}: {where}.{key}: unknown key (allowed: "
                             f"{', '.join(RANGE_KEYS)})")
    low, high = value.get("from"), value.get("to")
    for key, bound in (("from", low), ("to", high)):
        if not (_number(bound) and math.isfinite(bound)):
            raise SweepError(f"{source}: {where}.{key}: must be a finite number, got {bound!r}")
    spacing = value.get("spacing", "linear")
    if spacing not in SPACINGS:
        raise SweepError(f"{source}: {where}.spacing: must be one of {', '.join(SPACINGS)}, "
                         f"got {spacing!r}")
    if spacing == "log" and not (low > 0 and high > 0):
        raise SweepError(f"{source}: {where}: spacing = \"log\" needs from > 0 and to > 0")
    if mode == "sample":
        if "num" in value:
            raise SweepError(f"{source}: {where}.num: mode = \"sample\" takes samples from the "
                             "spec, not num per axis")
        return Axis(number, low=float(low), high=float(high), spacing=spacing)
    num = value.get("num")
    if not (_integer(num) and num >= 1):
        raise SweepError(f"{source}: {where}.num: must be an integer >= 1, got {num!r}")
    if num > MAX_RUNS:
        raise SweepError(f"{source}: {where}.num: {num} values, more than the {MAX_RUNS} runs "
                         "a sweep may have")
    return Axis(number, low=float(low), high=float(high), spacing=spacing, num=num)


def _expand(axes, mode, samples, sampler, seed, source) -> Runs:
    if mode == "product":
        # The count from the axes' lengths, before any range's values are made.
        count = math.prod(axis.size for axis in axes)
        if count > MAX_RUNS:
            raise SweepError(f"{source}: axes: {count} runs, more than {MAX_RUNS}")
        grids = np.meshgrid(*[axis.grid() for axis in axes], indexing="ij")
        return Runs({axis.path: grid.ravel() for axis, grid in zip(axes, grids)})
    if mode == "zip":
        return Runs({axis.path: axis.grid() for axis in axes})
    from scipy.stats import qmc

    if sampler == "sobol":
        # The first `samples` points of the scrambled Sobol sequence, drawn as the power of two
        # that holds them: the same points as random(samples), without SciPy's warning that
        # only a power of two keeps the sequence's balance (docs/sweep-format.md, section 4).
        power = max(0, math.ceil(math.log2(samples)))
        unit = qmc.Sobol(len(axes), scramble=True, seed=seed).random_base2(power)[:samples]
    else:
        unit = qmc.LatinHypercube(len(axes), seed=seed).random(samples)
    columns = {}
    for axis, u in zip(axes, unit.T):
        if axis.spacing == "log":
            low, high = math.log(axis.low), math.log(axis.high)
            columns[axis.path] = np.exp(low + u * (high - low))
        else:
            columns[axis.path] = axis.low + u * (axis.high - axis.low)
    return Runs(columns)


def _check_values(spec: SweepSpec) -> None:
    """Every run's values against the scene's own rules (checks.py: screened with numpy, the
    suspects judged by the scene reader): the first one out of range is named with its axis
    and run."""
    runs = spec.runs

    def describe(index: int) -> str:
        return ", ".join(f"{path} = {value:g}" for path, value in runs[index].items())

    check_runs(spec.scene, runs.columns, spec.source, describe, SweepError)


#: t_end / dt is a whole number of steps when it is within this relative distance of one (the
#: round-off of the division and of the two numbers' decimal spellings, with a wide margin).
WHOLE_STEPS_RTOL = 1e-9


def _check_whole_steps(spec: SweepSpec, dts: np.ndarray, ends: np.ndarray,
                       ratio: np.ndarray) -> None:
    """Every run's t_end a whole number of its steps of dt (to round-off): a run takes
    round(t_end / dt) steps, as `chaingen simulate` does, so any other t_end would be a number
    the table records and the run did not use. The first other is named with its run and the
    whole-step values near it (of the t_end axis, or else of the dt axis, or else of t_end)."""
    with np.errstate(all="ignore"):
        steps = np.maximum(np.rint(ratio), 1.0)
        off = np.flatnonzero(~(np.abs(ratio - steps) <= WHOLE_STEPS_RTOL * steps))
    if not len(off):
        return
    index = int(off[0])
    dt, t_end, r = float(dts[index]), float(ends[index]), float(ratio[index])
    below, above = max(1, math.floor(r)), max(1, math.floor(r)) + (r >= 1)
    counts = sorted({below, above})
    axes = spec.runs.columns
    if "simulation.t_end" in axes or "simulation.dt" not in axes:
        key = 'axes."simulation.t_end"' if "simulation.t_end" in axes else "t_end"
        near = " or ".join(f"{count * dt:.12g} ({_steps(count)})" for count in counts)
        what = f"t_end values near it that are whole steps: {near}"
    else:
        key = 'axes."simulation.dt"'
        near = " or ".join(f"{t_end / count:.12g} ({_steps(count)})" for count in counts)
        what = f"dt values near it that divide t_end: {near}"
    run = f"run {index}: " if key.startswith("axes") else ""
    raise SweepError(f"{spec.source}: {key}: {run}t_end = {t_end:.12g} s is {r:.6g} steps of "
                     f"dt = {dt:.12g} s, not a whole number (a run takes round(t_end / dt) "
                     f"steps); {what}")


def _steps(count: int) -> str:
    return f"{count} step{'s' if count != 1 else ''}"


def _check_sizes(spec: SweepSpec) -> None:
    """Step counts and sample sizes within simulate's limits (MAX_STEPS, MAX_SAMPLE_BYTES):
    a run's steps, the samples a chunk of runs holds in memory, the trajectories on disk."""
    runs, n = spec.runs, spec.scene.n
    dts = runs.columns.get("simulation.dt", np.full(len(runs), spec.scene.simulation.dt))
    ends = runs.columns.get("simulation.t_end", np.full(len(runs), spec.t_end))
    with np.errstate(all="ignore"):
        ratio = ends / dts
    over = np.flatnonzero(~(ratio <= MAX_STEPS))
    if len(over):
        index = int(over[0])
        key = ("axes" if {"simulation.dt", "simulation.t_end"} & set(runs.columns)
               else "t_end")
        raise SweepError(f"{spec.source}: {key}: run {index}: t_end / dt = {ratio[index]:.3g} "
                         f"steps, more than the {MAX_STEPS:.0e} a run may take (dt = "
                         f"{dts[index]:g} s, t_end = {ends[index]:g} s)")
    _check_whole_steps(spec, dts, ends, ratio)
    if not spec.every:
        return
    samples = spec.sample_count()
    row = (2 * n + 3) * 8
    held = spec.chunk * samples * row
    if held > MAX_SAMPLE_BYTES:
        raise SweepError(f"{spec.source}: every: {samples} samples a run, {spec.chunk} runs a "
                         f"chunk would hold {held / 2 ** 30:.1f} GiB of samples (limit "
                         f"{MAX_SAMPLE_BYTES / 2 ** 30:.0f} GiB); keep fewer with a larger every")
    stored = len(runs) * samples * row
    if stored > MAX_TRAJECTORY_BYTES:
        raise SweepError(f"{spec.source}: every: {len(runs)} runs of {samples} samples would "
                         f"store {stored / 2 ** 40:.1f} TiB of trajectories (limit "
                         f"{MAX_TRAJECTORY_BYTES / 2 ** 40:.0f} TiB); keep fewer with a larger "
                         "every")
