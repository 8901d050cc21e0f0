"""The contract's C types seen from Python: ctypes structures, signatures and NewtonOptions.

Everything here is built from chaingen.runtime.contract (the fields of the options and stats
structs) and from a package's manifest (the parameter list of each entry point it exports), so
the loader never states a C signature of its own.
"""
from __future__ import annotations

import ctypes
import dataclasses

from . import contract

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
    }
    options = dataclasses.make_dataclass("NewtonOptions", fields, namespace=namespace,
                                         frozen=True)
    options.__module__ = __name__
    return options


def _check_options(options) -> None:
    for field in contract.NEWTON_OPTIONS:     # a C int would wrap a larger value silently
        value = getattr(options, field.name)
        if field.c_type == "int" and not -2 ** 31 <= value < 2 ** 31:
            raise ValueError(f"NewtonOptions.{field.name}: must fit a C int, got {value!r}")
    for name in contract.ADAPTIVE_TOLERANCES:
        value = getattr(options, name)
        if not contract.is_adaptive_tolerance(value):
            raise ValueError(f"NewtonOptions.{name}: must be {contract.ADAPTIVE_TOLERANCE_RULE}, "
                             f"got {value!r}")
    modes = tuple(mode.value for mode in contract.JACOBIAN_MODES)
    if options.reuse_jacobian not in modes:
        names = ", ".join(f"{mode.value} {mode.comment}" for mode in contract.JACOBIAN_MODES)
        raise ValueError(f"NewtonOptions.reuse_jacobian: must be one of {names}, got "
                         f"{options.reuse_jacobian!r}")


NewtonOptions = _newton_options_class()
