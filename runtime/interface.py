"""The contract's C types seen from Python: ctypes structures, signatures, NewtonOptions, and
the one conversion of a user's numbers to C doubles.

Everything here is built from chaingen.runtime.contract (the fields of the options and stats
structs) and from a package's manifest (the parameter list of each entry point it exports), so
the loader never states a C signature of its own. Every number a user gives the runtime for C
(states, angles, rates, torques, parameter values, dt, tolerances) goes through `real_array` or
`real_number`: numpy alone would take True as 1.0 and '2.0' as 2.0, and drop the imaginary part
of a complex number with only a warning.
"""
from __future__ import annotations

import ctypes
import dataclasses
import math
import operator

import numpy as np

from . import contract

#: Values numpy would turn into a float that are no real number a user meant (None is NaN).
_NOT_REAL = (bool, np.bool_, str, bytes, complex, np.complexfloating, type(None))
_REAL = object()     # what _not_real finds in real numbers


def _not_real(values):
    """The first value in `values` (nested lists, tuples, object arrays) that is a bool, a
    complex number, a string or None, or _REAL if there is none."""
    if isinstance(values, np.ndarray):
        if values.dtype.kind in "fiu":
            return _REAL
        if values.dtype.kind != "O":
            return values.flat[0] if values.size else values.dtype
        values = values.flat
    elif not isinstance(values, (list, tuple)):
        return values if isinstance(values, _NOT_REAL) else _REAL
    for item in values:
        found = _not_real(item)
        if found is not _REAL:
            return found
    return _REAL


def real_array(values, name: str, shape: tuple | None = None, *,
               noun: str = "real numbers") -> np.ndarray:
    """`values` as a contiguous float64 array (of `shape`, if given), `name` naming them in a
    one-line error: real numbers only (a bool, complex number, string or None is a
    TypeError, and so is a masked entry, whose hidden value numpy would take)."""
    if np.ma.is_masked(values):
        raise TypeError(f"{name}: must be {noun}, got a masked entry (a missing value)")
    if not (type(values) is np.ndarray and values.dtype.kind in "fiu"):
        found = _not_real(values)
        if found is _REAL and not isinstance(values, (list, tuple)):
            found = _not_real(np.asarray(values))    # a Series, a 0-d array, ...
        if found is not _REAL:
            what = found if isinstance(found, np.dtype) else f"{type(found).__name__} {found!r}"
            raise TypeError(f"{name}: must be {noun}, got {what}")
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as error:    # ragged: ValueError; 10**400
        raise type(error)(f"{name}: must be {noun} ({error})") from None
    if shape is not None or not array.flags.c_contiguous:
        array = np.ascontiguousarray(array)      # with a shape: a scalar is one entry
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} must have {shape[0] if len(shape) == 1 else shape} entries, "
                         f"got shape {array.shape}")
    return array


def real_number(value, name: str) -> float:
    """`value` as a float, `name` naming it in a one-line error: a real number only."""
    if isinstance(value, float):     # np.float64 too; no bool, complex or str is one
        return float(value)
    array = real_array(value, name, noun="a real number")
    if array.shape != ():
        raise TypeError(f"{name}: must be a real number, got {type(value).__name__} of shape "
                        f"{array.shape}")
    return float(array)


def step_length(dt, what: str) -> float:
    """dt of a step function: required, after u as in C (step(x0, u, dt)), > 0 and finite."""
    if dt is None:
        raise TypeError(f"{what}() needs dt; the arguments are in C's order: {what}(x0, u, dt) "
                        f"(u=None for an unactuated scene), e.g. {what}(x0, dt=0.01)")
    return positive_step(dt)


def positive_step(dt) -> float:
    """dt as a float, > 0 and finite (C refuses any other as a 'bad argument', which named
    nothing; no entry point integrates backwards), else a one-line ValueError naming it."""
    dt = real_number(dt, "dt")
    if not 0.0 < dt < np.inf:
        raise ValueError(f"dt: must be > 0 and finite, got {dt!r}")
    return dt


#: The largest angle (rad) a chain starts from, 2^20 rad (166,886 turns): below it a double
#: holds an angle to 2^-33 = 1.16e-10 rad or finer, about what a step resolves its unknowns to
#: (the Newton option update_rtol, 1e-10). Beyond it every step rounds the angle it moves by
#: more: from 1e10 rad (held to 1.9e-6 rad) midpoint's first step fails (a spurious root),
#: and es ran on silently, 7.4e-7 rad off the same start given within its turn after 1 s
#: (4.8e-5 at 1e12, 0.06 rad at 1e15). Angles are not wrapped for the user: a control target
#: makes the physics non-periodic. The scene readers (initial.angles[i]) and
#: Solver.initial_state (so simulate and a Stepper) refuse such angles.
MAX_INITIAL_ANGLE = 2.0 ** 20


def far_angle(angles) -> tuple[int, float, str] | None:
    """(index, angle, what is wrong) of the first of the finite `angles` beyond
    MAX_INITIAL_ANGLE, or None."""
    for index, angle in enumerate(angles):
        if abs(angle) >= MAX_INITIAL_ANGLE:
            angle = float(angle)
            return index, angle, (
                f"must be within +-2^20 = {MAX_INITIAL_ANGLE:.0f} rad (an angle in rad): a "
                f"double holds {angle:g} rad only to {math.ulp(angle):.2g} rad, coarser than "
                "the 1e-10 of its unknowns a step resolves (update_rtol), so every step rounds "
                "the motion it takes; subtract whole turns (2 pi k), from a [control] target "
                "too")
    return None


def held_angles(array: np.ndarray, name: str) -> np.ndarray:
    """`array` (finite angles) if every entry is within MAX_INITIAL_ANGLE, else a one-line
    ValueError naming `name`, the entry and why (far_angle)."""
    refused = far_angle(array)
    if refused is not None:
        index, angle, what = refused
        raise ValueError(f"{name}[{index}]: {what}, got {angle!r}")
    return array


def finite(array: np.ndarray, name: str) -> np.ndarray:
    """`array` if every entry is finite, else a one-line ValueError naming `name` and the
    first entry that is not (C refuses a NaN or Inf in a state, posture or input as a 'bad
    argument', or, in simulate's torques, failed the step that reached it)."""
    if not np.isfinite(array).all():
        where = np.unravel_index(int(np.argmin(np.isfinite(array))), array.shape)
        index = ", ".join(map(str, where))
        raise ValueError(f"{name}: must be finite, got {float(array[where])!r} at [{index}]")
    return array


_C_SCALARS = {"int": ctypes.c_int, "long": ctypes.c_long, "double": ctypes.c_double,
              "size_t": ctypes.c_size_t, "volatile int": ctypes.c_int,
              "volatile long": ctypes.c_long}


def _struct(name: str, fields) -> type[ctypes.Structure]:
    return type(name, (ctypes.Structure,), {
        "_fields_": [(field.name, _C_SCALARS[field.c_type]) for field in fields]})


#: <prefix>_options, <prefix>_stats and <prefix>_control, field by field as the header
#: declares them.
OptionsStruct = _struct("OptionsStruct", contract.NEWTON_OPTIONS)
StatsStruct = _struct("StatsStruct", contract.STATS_FIELDS)
ControlStruct = _struct("ControlStruct", contract.CONTROL_FIELDS)


def ctypes_type(c_type: str, prefix: str):
    """The ctypes type of a C type of the contract (prefix resolved), None for void."""
    if c_type == "void":
        return None
    if c_type in _C_SCALARS:
        return _C_SCALARS[c_type]
    if c_type in ("double *", "const double *"):
        return ctypes.POINTER(ctypes.c_double)
    if c_type == "int *":
        return ctypes.POINTER(ctypes.c_int)
    if c_type == "const char *":
        return ctypes.c_char_p
    if c_type in (f"{prefix}_options *", f"const {prefix}_options *"):
        return ctypes.POINTER(OptionsStruct)
    if c_type == f"{prefix}_stats *":
        return ctypes.POINTER(StatsStruct)
    if c_type == f"{prefix}_control *":
        return ctypes.POINTER(ControlStruct)
    # The observer is for C callers; Python passes NULL and follows a run through its control
    # block instead. A controller is passed as the address of a C function (Solver.simulate
    # makes one of a Python callable).
    if c_type in (f"{prefix}_workspace *", "void *", f"{prefix}_observer",
                  f"{prefix}_controller"):
        return ctypes.c_void_p
    raise ValueError(f"no ctypes type for the C type {c_type!r}")


#: Why adaptive steps are refused with a control law held from the step's start (a scene's
#: control.law = "sampled": a package's manifest's control_law, its model table's held_control,
#: for which C's simulate loops return BAD_ARGUMENT). What every reader says after the option.
HELD_LAW_REFUSAL = ("adaptive steps would hold the sampled law (control.law = \"sampled\") "
                    "over each adaptive step instead of the sample period dt; take fixed steps")


def _for_simulate(options, control_law: str | None) -> OptionsStruct:
    """The C options of simulate in a package whose step has the law `control_law` (the
    manifest's: "discrete", "sampled" or None): rtol or atol > 0 with the sampled law, whose
    hold period they would change from dt, is a one-line ValueError, as C refuses it."""
    if control_law == "sampled":
        for name in contract.ADAPTIVE_TOLERANCES:
            if getattr(options, name):
                raise ValueError(f"simulate: {name}: {HELD_LAW_REFUSAL}, got "
                                 f"{getattr(options, name):g}")
    return options.as_c()


def _newton_options_class():
    fields = [(field.name, field.python_type,
               dataclasses.field(default=field.python_type(field.default)))
              for field in contract.NEWTON_OPTIONS]
    namespace = {
        "__doc__": "Newton settings of the generated step, the fields of <prefix>_options (the "
                   "generated header documents them). The defaults here are the contract's "
                   "(full Newton); a Solver's `default_options` are its package's.",
        "__post_init__": _check_options,
        "as_c": lambda self: OptionsStruct(*[
            int(value) if isinstance(value, bool) else value
            for value in dataclasses.astuple(self)]),
        "for_simulate": _for_simulate,
    }
    options = dataclasses.make_dataclass("NewtonOptions", fields, namespace=namespace,
                                         frozen=True)
    options.__module__ = __name__
    return options


def option_refusal(field, value) -> str | None:
    """What an options field must be ("must be > 0 and finite") if `value` (of the field's
    Python type) is out of its range (its `lower` bound; a double must be finite), else None:
    the one rule of the Python runtime and the command line."""
    if field.name in contract.ADAPTIVE_TOLERANCES:
        return None       # their own rule: contract.is_adaptive_tolerance
    bound, double = field.lower, field.c_type == "double"
    if (double and not np.isfinite(value)) or (bound is not None and not bound.admits(value)):
        rule = " and ".join(([bound.rule] if bound else []) + (["finite"] if double else []))
        return f"must be {rule}"
    return None


def _option_value(field, value):
    """The value of an options field as its Python type: a switch True, False, 1 or 0, an int
    field an integer (not a bool), a double a real number; anything else (a string, 2.5
    iterations, True iterations) is refused rather than converted, and so is a value out of
    the field's range (option_refusal: 0 iterations, a NaN or negative tolerance)."""
    name = f"NewtonOptions.{field.name}"
    if field.switch:
        if isinstance(value, (bool, np.bool_)) or (
                isinstance(value, (int, np.integer)) and value in (0, 1)):
            return bool(value)
        raise TypeError(f"{name}: must be True or False (or 1, 0), got {value!r}")
    if field.python_type is int:
        try:
            if isinstance(value, (bool, np.bool_)):
                raise TypeError
            value = operator.index(value)
        except TypeError:
            raise TypeError(f"{name}: must be an integer, got {value!r}") from None
        if not -2 ** 31 <= value < 2 ** 31:     # a C int would wrap it silently
            raise ValueError(f"{name}: must fit a C int, got {value!r}")
    else:
        value = real_number(value, name)
    refused = option_refusal(field, value)
    if refused:
        raise ValueError(f"{name}: {refused}, got {value!r}")
    return value


def _check_options(options) -> None:
    modes = tuple(mode.value for mode in contract.JACOBIAN_MODES)
    if options.reuse_jacobian not in modes:
        names = ", ".join(f"{mode.value} {mode.comment}" for mode in contract.JACOBIAN_MODES)
        raise ValueError(f"NewtonOptions.reuse_jacobian: must be one of {names}, got "
                         f"{options.reuse_jacobian!r}")
    for field in contract.NEWTON_OPTIONS:     # frozen: set through object.__setattr__
        object.__setattr__(options, field.name,
                           _option_value(field, getattr(options, field.name)))
    for name in contract.ADAPTIVE_TOLERANCES:
        value = getattr(options, name)
        if not contract.is_adaptive_tolerance(value):
            raise ValueError(f"NewtonOptions.{name}: must be {contract.ADAPTIVE_TOLERANCE_RULE}, "
                             f"got {value!r}")


NewtonOptions = _newton_options_class()
