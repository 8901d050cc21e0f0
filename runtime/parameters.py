"""A package's run-time parameter values as the user gives them: read by name or in order,
checked against the ranges the scene format allows (the manifest records them).

A mapping (a dict, a pandas Series indexed by key path, anything with keys() and [] by label) is
read by name, never by position: a Series whose paths come in another order than
`Solver.parameters` gives each number to its own path. Other labelled values a positional read
would misplace (an xarray DataArray, a numpy structured array) are refused.
"""
from __future__ import annotations

import functools
from collections.abc import Mapping

import numpy as np

from .interface import far_angle, real_array, real_number
from .keypaths import spelling_error


def parameter_bounds(entries: list) -> tuple[np.ndarray, np.ndarray] | None:
    """(lower bounds, whether each is allowed) of the run-time parameters from the manifest,
    -inf where there is none; None for a manifest that records no ranges."""
    if not all("lower" in entry and "lower_inclusive" in entry for entry in entries):
        return None
    return (np.array([-np.inf if entry["lower"] is None else float(entry["lower"])
                      for entry in entries], dtype=float),
            np.array([bool(entry["lower_inclusive"]) for entry in entries], dtype=bool))


def _named(values) -> list | None:
    """The (name, value) pairs of a mapping or of anything read as one (keys() and [] by
    label, as a pandas Series), else None."""
    if isinstance(values, Mapping) or (hasattr(values, "keys") and hasattr(values, "__getitem__")
                                       and not isinstance(values, np.ndarray)):
        keys = list(values.keys())
        for index, key in enumerate(keys):
            if key in keys[:index]:      # a Series' labels may repeat
                raise ValueError(f"parameters: {key} given twice")
        return [(key, values[key]) for key in keys]
    return None


def _labelled(values) -> bool:
    """Whether `values` carry labels a positional read would ignore."""
    return (any(hasattr(values, name) for name in ("coords", "dims", "columns")) or
            getattr(getattr(values, "dtype", None), "names", None) is not None)


def no_values(values) -> bool:
    """Whether `values` is an empty sequence or mapping (a scalar has no length)."""
    try:
        return len(values) == 0
    except TypeError:
        return False


def parameter_vector(given, paths: tuple, defaults: np.ndarray, bounds, prefix: str):
    """The parameter vector p of a package `prefix` whose parameters are `paths`: `defaults`
    with the values `given` (None, a mapping by path, or all of them in the order of `paths`),
    each in its range `bounds` (parameter_bounds)."""
    if given is None:
        return defaults.copy()
    named = _named(given)
    if named is not None:
        values = defaults.copy()
        for path, value in named:
            if path not in paths:
                refused = spelling_error(path)
                raise ValueError(refused or f"{prefix} has no parameter {path!r} (its "
                                 f"parameters: {', '.join(paths) or 'none'})")
            values[paths.index(path)] = real_number(value, path)
    elif _labelled(given):
        raise TypeError(f"parameters: a {type(given).__name__} would be read by position, not "
                        "by its labels: give a mapping of key paths, or the values in the "
                        "order of Solver.parameters")
    else:
        values = real_array(given, "parameters", (len(paths),))
    _check_ranges(values, paths, bounds, prefix)
    return values


@functools.lru_cache(maxsize=64)
def _targets(paths: tuple) -> tuple[int, ...]:
    """The indices of the control.target entries among `paths` (a package's, cached)."""
    return tuple(i for i, path in enumerate(paths) if path.startswith("control.target["))


def _check_ranges(values: np.ndarray, paths: tuple, bounds, prefix: str) -> None:
    """ValueError naming the first value out of its range, as the scene reader words it."""
    if bounds is None:
        raise ValueError(f"{prefix}: its manifest gives no range of its parameters (made by an "
                         "older chaingen): generate the package again")
    lower, inclusive = bounds
    good = np.isfinite(values) & ((values > lower) | (inclusive & (values == lower)))
    if good.all():
        for index in _targets(paths):       # an angle, as a scene's control.target
            refused = far_angle([values[index]])
            if refused:
                raise ValueError(f"{paths[index]}: {refused[2]}, got {float(values[index])!r}")
        return
    index = int(np.argmin(good))
    value = float(values[index])
    rule = ("must be finite" if not np.isfinite(value) else
            f"must be {'>=' if inclusive[index] else '>'} {float(lower[index]):g}")
    raise ValueError(f"{paths[index]}: {rule}, got {value!r}")
