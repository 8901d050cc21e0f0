"""The sweep spec (docs/sweep-format.md): which scene, which numbers vary, how, and what to keep.

    scene = "three_link_mono.toml"       # relative to the spec file
    method = "es"                        # optional, else the scene's
    mode = "product"                     # product | zip | sample
    [axes]
    "springs[0].stiffness" = [5.0, 10.0, 20.0]
    "links[1].mass" = { from = 0.5, to = 2.0, num = 16 }

As strict as a scene file: an unknown key, a path that names no number of the scene, a value
out of the scene's own range (checked for every run's value), zip axes of unequal length: each
a one-line SweepError naming the key, before anything runs or is written.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ChaingenError, SceneError
from ...runtime.contract import ADAPTIVE_TOLERANCE_RULE, ADAPTIVE_TOLERANCES, is_adaptive_tolerance
from ...scene import METHODS, QUADRATURE_RANGE, Scene, load_scene
from ...scene.parameters import NumberPath, number_path, with_values
from ...symbolic.composition import order_error, quadrature_error

MODES = ("product", "zip", "sample")
SAMPLERS = ("sobol", "latin-hypercube")
SPACINGS = ("linear", "log")
TOP_KEYS = ("scene", "method", "quadrature", "order", "rtol", "atol", "mode", "samples",
            "sampler", "seed", "t_end", "every", "axes")
RANGE_KEYS = ("from", "to", "num", "spacing")
#: A sweep of more runs than this is refused as a mistake (a product of long axes).
MAX_RUNS = 10_000_000


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

    @property
    def path(self) -> str:
        return self.number.path


@dataclass(frozen=True)
class SweepSpec:
    """A checked spec: the base scene, the scheme, the axes, and every run's values."""

    source: str
    scene_path: Path
    scene: Scene
    method: str
    quadrature: int
    mode: str
    axes: tuple[Axis, ...]
    runs: tuple[dict[str, float], ...] = field(repr=False)
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

    @functools.cached_property
    def digest(self) -> str:
        """What identifies the sweep's results: the expanded spec and the base scene (as read
        when the spec was checked, so a worker elsewhere needs no scene file)."""
        text = json.dumps({"document": self.document, "scene": self.scene_text,
                           "runs": list(self.runs)}, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()

    def n_steps(self, run: dict[str, float]) -> int:
        dt = run.get("simulation.dt", self.scene.simulation.dt)
        t_end = run.get("simulation.t_end", self.t_end)
        return max(1, round(t_end / dt))


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
    """Check a spec document (a dict, as TOML or Python gives it)."""
    def fail(key: str, what: str) -> SweepError:
        return SweepError(f"{source}: {key}: {what}")

    for key in document:
        if key not in TOP_KEYS:
            raise fail(key, f"unknown key (allowed: {', '.join(TOP_KEYS)})")
    if "scene" not in document or not isinstance(document["scene"], str):
        raise fail("scene", "missing: the scene file (a string, relative to the spec file)")
    scene_path = (base / document["scene"]).resolve() if not Path(
        document["scene"]).is_absolute() else Path(document["scene"])
    try:
        scene = load_scene(scene_path)
    except SceneError as error:
        raise SweepError(f"{source}: scene: {error}") from None
    method = document.get("method", scene.simulation.method)
    if method not in METHODS:
        raise fail("method", f"must be one of {', '.join(METHODS)}, got {method!r}")
    quadrature = document.get("quadrature", scene.simulation.quadrature)
    low, high = QUADRATURE_RANGE
    if not (_integer(quadrature) and low <= quadrature <= high):
        raise fail("quadrature", f"must be an integer from {low} to {high}, got {quadrature!r}")
    order = document.get("order", scene.simulation.order)
    refused = order_error(method, order) if _integer(order) else "must be an integer"
    if refused:
        raise fail("order", refused)
    refused = quadrature_error(method, order, quadrature)
    if refused:
        raise fail("quadrature", refused)
    tolerances = {}
    for name in ADAPTIVE_TOLERANCES:
        value = document.get(name, getattr(scene.simulation, name))
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not is_adaptive_tolerance(float(value)):
            raise fail(name, f"must be {ADAPTIVE_TOLERANCE_RULE}, got {value!r}")
        tolerances[name] = float(value)
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
    if mode == "zip":
        lengths = {axis.path: len(axis.values) for axis in axes}
        if len(set(lengths.values())) > 1:
            raise fail("axes", "zip axes must have equal lengths, got "
                               + ", ".join(f"{path}: {count}" for path, count in lengths.items()))
    runs = _expand(axes, mode, samples, sampler, seed, source)
    if len(runs) > MAX_RUNS:
        raise fail("axes", f"{len(runs)} runs, more than {MAX_RUNS}")
    spec = SweepSpec(source=source, scene_path=scene_path, scene=scene, method=method,
                     quadrature=quadrature, mode=mode, axes=axes, runs=tuple(runs),
                     t_end=float(t_end), every=every, seed=seed, sampler=sampler,
                     document=document, scene_text=scene_path.read_text(encoding="utf-8"),
                     order=order, **tolerances)
    _check_values(spec)
    return spec


def _integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _axis(scene: Scene, path: str, value, mode: str, source: str) -> Axis:
    where = f"axes.{json.dumps(path)}"
    try:
        number = number_path(scene, path)
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
    grid = (np.geomspace(low, high, num) if spacing == "log" else np.linspace(low, high, num))
    return Axis(number, values=tuple(float(item) for item in grid), spacing=spacing)


def _expand(axes, mode, samples, sampler, seed, source) -> list[dict[str, float]]:
    if mode == "product":
        count = math.prod(len(axis.values) for axis in axes)
        if count > MAX_RUNS:
            raise SweepError(f"{source}: axes: {count} runs, more than {MAX_RUNS}")
        grids = np.meshgrid(*[np.array(axis.values) for axis in axes], indexing="ij")
        columns = [grid.ravel() for grid in grids]
        return [{axis.path: float(column[k]) for axis, column in zip(axes, columns)}
                for k in range(count)]
    if mode == "zip":
        return [{axis.path: axis.values[k] for axis in axes}
                for k in range(len(axes[0].values))]
    from scipy.stats import qmc

    if sampler == "sobol":
        unit = qmc.Sobol(len(axes), scramble=True, seed=seed).random(samples)
    else:
        unit = qmc.LatinHypercube(len(axes), seed=seed).random(samples)
    runs = []
    for row in unit:
        run = {}
        for axis, u in zip(axes, row):
            if axis.spacing == "log":
                run[axis.path] = float(math.exp(math.log(axis.low)
                                                + u * (math.log(axis.high) - math.log(axis.low))))
            else:
                run[axis.path] = float(axis.low + u * (axis.high - axis.low))
        runs.append(run)
    return runs


def _check_values(spec: SweepSpec) -> None:
    """Every run's values against the scene's own rules: the first one out of range is named
    with its axis and run."""
    for index, run in enumerate(spec.runs):
        values = {path: value for path, value in run.items()
                  if not path.startswith("simulation.")}
        for path, value in run.items():
            if path.startswith("simulation.") and not (math.isfinite(value) and value > 0):
                raise SweepError(f"{spec.source}: axes.{json.dumps(path)}: run {index}: must be "
                                 f"> 0 and finite (s), got {value!r}")
        try:
            with_values(spec.scene, values, where="run")
        except SceneError as error:
            message = str(error).split(": ", 1)[1]
            raise SweepError(f"{spec.source}: axes: run {index} "
                             f"({', '.join(f'{p} = {v:g}' for p, v in run.items())}): "
                             f"{message}") from None
