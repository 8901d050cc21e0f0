"""A controller for `Solver.simulate(controller=...)` as the C loop calls it: the address of a
function of the package's <prefix>_controller type (contract.CONTROLLER_PARAMETERS).

A C controller (a ctypes function pointer or its address) is passed as it is; a Python
callable controller(t, phi, omega) -> torques is wrapped in a ctypes callback. The callback
runs in the thread that runs the C loop and holds the GIL while it runs.
"""
from __future__ import annotations

import ctypes

import numpy as np

from .interface import real_array

#: The C type of <prefix>_controller, for Python controllers; the arrays as plain addresses
#: (ints), which ctypes passes without building pointer objects.
_CONTROLLER = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_long, ctypes.c_double, ctypes.c_void_p,
                               ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)


def context_address(pointer) -> int | None:
    """The controller's void *context: None, an int address or a ctypes pointer or buffer."""
    if pointer is None or isinstance(pointer, int):
        return pointer
    try:
        return ctypes.cast(pointer, ctypes.c_void_p).value
    except ctypes.ArgumentError:
        raise ValueError(f"controller_context: an address (int), a ctypes pointer or None, got "
                         f"{type(pointer).__name__}") from None


def controller_address(controller, n: int, nu: int, errors: list, context=None):
    """(address of a C controller, the ctypes callback to keep alive or None, the address of
    its context) for a chain of n joints with nu inputs. An exception a Python controller
    raises goes to `errors` and stops the run (the callback returns 1). A context is for a C
    controller only (a Python controller was run without the one it was given)."""
    if isinstance(controller, ctypes._CFuncPtr):
        return ctypes.cast(controller, ctypes.c_void_p).value, None, context_address(context)
    if isinstance(controller, int) and not isinstance(controller, bool):
        if controller == 0:
            raise ValueError("controller: the address of a C function, got 0 (NULL)")
        return controller, None, context_address(context)
    if not callable(controller):
        raise ValueError(f"controller: a callable controller(t, phi, omega) -> torques, or "
                         f"a C function pointer, got {type(controller).__name__}")
    if context is not None:
        raise ValueError("controller_context: for a C controller; a Python controller keeps "
                         "its own state (a closure, an object's method)")
    views: dict[int, np.ndarray] = {}    # the C loop's arrays by address (they stay put)

    def view(address: int, size: int) -> np.ndarray:
        array = views.get(address)
        if array is None:
            array = views[address] = np.frombuffer(
                (ctypes.c_double * size).from_address(address), dtype=np.float64)
        return array

    def call(step, t, phi, omega, u, context) -> int:
        try:
            value = controller(t, view(phi, n).copy(), view(omega, n).copy())
            torques = real_array(value, "controller: its torques")
            if torques.shape != (nu,) or not np.all(np.isfinite(torques)):
                raise ValueError(f"controller: must return {nu} finite torques, got "
                                 f"{value!r} at t = {t:g} s")
            view(u, nu)[:] = torques
            return 0
        except BaseException as error:   # raised again once the run has stopped
            errors.append(error)
            return 1

    callback = _CONTROLLER(call)
    return ctypes.cast(callback, ctypes.c_void_p).value, callback, None
