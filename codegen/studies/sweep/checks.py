"""Every run's values of a sweep against the scene format's rules, in bounded time.

A run is a scene with some numbers replaced, and the scene reader (`with_values`) is the judge
of whether that scene is valid, with its own messages. Calling the reader for each of 10^6 runs
takes minutes, so the runs are first screened column by column with numpy: each number's own
range (contract.NUMBER_BOUNDS: a mass > 0, a rest length >= 0, ...) and magnitude (beyond
LARGE, where the reader's overflow checks apply, or below SMALL, where its underflow checks
do; an initial angle from MAX_INITIAL_ANGLE),
and, when the varied numbers move a spring's fastenings, its segments' lengths at the initial
angles. The screen is generous (a run near a limit is suspect too); the reader then judges
the suspects in run order and the first it refuses is the error. A run the screen passes is
one the reader accepts: the screen's rules are the reader's (tests/test_sweep_properties.py
compares them on drawn values).
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable

import numpy as np

from ...errors import SceneError
from ...runtime.contract import lower_bound
from ...scene import Scene
from ...scene.kinematics import ZERO_SEGMENT_RELATIVE_TOLERANCE
from ...scene.solver_spec import numbers_of
from ...scene.values import MAX_INITIAL_ANGLE
from ...spatial.values import SpatialScene

#: Runs screened at once (bounded memory).
BLOCK = 65_536
#: A varied number beyond this magnitude makes its run a suspect: the reader refuses a chain
#: whose mass matrix, gravity torques or energies at the start overflow a double (a com of
#: 1e200 m, a rest length of 1e300 m), which takes products of such numbers.
LARGE = 1e30
#: And one below this magnitude, but 0: the reader refuses a chain whose lengths' squares or
#: mass matrix underflow a double (lengths of 1e-300 m; masses of 1e-200 kg at 1e-60 m).
SMALL = 1e-30


def _geometric(path: str) -> bool:
    """Whether the number moves a spring's fastenings at the initial configuration."""
    return (path.startswith("initial.angles[") or path == "base.fastening"
            or path.endswith(".length") or path.endswith(".fastening")
            or ".offsets[" in path)


def suspects(scene: Scene | SpatialScene, columns: dict[str, np.ndarray], first: int,
             count: int) -> np.ndarray:
    """Indices (from `first`) of runs [first, first + count) that the reader may refuse."""
    bad = np.zeros(count, dtype=bool)
    block = {path: column[first:first + count] for path, column in columns.items()}
    for path, values in block.items():
        bad |= ~(np.abs(values) <= LARGE)      # also inf and NaN
        bad |= (np.abs(values) < SMALL) & (values != 0)
        if path.startswith("initial.angles["):     # the reader's MAX_INITIAL_ANGLE
            bad |= ~(np.abs(values) < MAX_INITIAL_ANGLE)
        bound = lower_bound(path)     # the scene format's, stated once (the reader's too)
        if bound is not None:
            bad |= ~(values >= bound.value if bound.inclusive else values > bound.value)
    if scene.springs and any(_geometric(path) for path in block):
        if isinstance(scene, SpatialScene):
            # A spatial scene's varied geometry is its initial angles alone (its COMs, joints
            # and routes are compiled): every such run is judged by the reader.
            bad[:] = True
        else:
            bad |= _short_segments(scene, block, count)
    return np.flatnonzero(bad) + first


def _short_segments(scene: Scene, block: dict[str, np.ndarray], count: int) -> np.ndarray:
    """Runs whose spring segments at the initial angles are near the reader's zero length
    (kinematics.spring_geometry, vectorised over runs; within a factor 4 of the limit)."""
    n = scene.n

    def column(path: str, default: float) -> np.ndarray:
        values = block.get(path)
        return np.full(count, default) if values is None else np.asarray(values, dtype=float)

    phi = np.column_stack([column(f"initial.angles[{i}]", scene.initial_angles[i])
                           for i in range(n)])
    lengths = np.column_stack([column(f"links[{i}].length", link.length)
                               for i, link in enumerate(scene.links)])
    chain_r = np.column_stack([column("base.fastening", scene.base_fastening)]
                              + [column(f"links[{i}].fastening", link.fastening)
                                 for i, link in enumerate(scene.links)])
    with np.errstate(all="ignore"):
        theta = np.cumsum(phi, axis=1)
        directions = np.stack([np.cos(theta), np.sin(theta)], axis=2)
        normals = np.concatenate([np.broadcast_to([0.0, 1.0], (count, 1, 2)),
                                  np.stack([-np.sin(theta), np.cos(theta)], axis=2)], axis=1)
        joints = np.concatenate([np.zeros((count, 1, 2)),
                                 np.cumsum(lengths[:, :, None] * directions, axis=1)], axis=1)
        size = lengths.sum(axis=1) + np.abs(chain_r).sum(axis=1)
        near = np.zeros(count, dtype=bool)
        for index, spring in enumerate(scene.springs):
            rows = slice(spring.first - 1, spring.last + 1)
            if spring.offsets is not None:
                r = np.column_stack([column(f"springs[{index}].offsets[{k}]", value)
                                     for k, value in enumerate(spring.offsets)])
                spring_size = size + np.abs(r).sum(axis=1)
            else:
                r, spring_size = chain_r[:, rows], size
            points = joints[:, rows] + r[:, :, None] * normals[:, rows]
            segments = np.diff(points, axis=1)
            lengths_j = np.hypot(segments[:, :, 0], segments[:, :, 1])
            limit = 4 * ZERO_SEGMENT_RELATIVE_TOLERANCE * spring_size + 1e-300
            near |= ~(lengths_j.min(axis=1) >= limit)
    return near


def check_runs(scene: Scene | SpatialScene, columns: dict[str, np.ndarray], source: str,
               describe: Callable[[int], str], error: type[Exception]) -> None:
    """`error` (one line) naming the first run the scene reader refuses, with its values
    (`describe`) and the reader's message; `source` is the spec file."""
    total = len(next(iter(columns.values()))) if columns else 0
    for first in range(0, total, BLOCK):
        count = min(BLOCK, total - first)
        for index in suspects(scene, columns, first, count):
            run = {path: float(column[index]) for path, column in columns.items()}
            for path, value in run.items():
                if path.startswith("simulation.") and not (math.isfinite(value) and value > 0):
                    raise error(f"{source}: axes.{json.dumps(path)}: run {index}: must be "
                                f"> 0 and finite (s), got {value!r}")
            values = {path: value for path, value in run.items()
                      if not path.startswith("simulation.")}
            try:
                numbers_of(scene).with_values(scene, values, where="run")
            except SceneError as refused:
                message = str(refused).split(": ", 1)[1]
                raise error(f"{source}: axes: run {index} ({describe(int(index))}): "
                            f"{message}") from None
