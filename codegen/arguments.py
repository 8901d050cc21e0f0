"""The command line's option types and shared options: numbers and paths as argparse reads them,
the scheme options, the run-time parameters, the Newton options of the C-interface contract;
and the scene a command is given, planar or spatial, told apart here once."""
from __future__ import annotations

import argparse
import functools
import os
from pathlib import Path

from .runtime import contract
from .runtime.interface import option_refusal
from .scene import Scene
from .scene.solver_rules import (
    GALERKIN_MIN_QUADRATURE,
    GALERKIN_ORDER,
    GRADIENTS,
    METHODS,
    ORDERS,
    request_refusal,
)
from .spatial import SpatialScene
from .spatial.reader import load_either_scene
from .spatial.values import SPATIAL_DEFAULT_METHOD

#: The orders of the step each method takes (chaingen.scene.solver_rules), said once.
ORDERS_TAKEN = (f"every method: {', '.join(map(str, ORDERS[:-1]))} and {ORDERS[-1]}; es at "
                f"{GALERKIN_ORDER} composes its k = 1 Galerkin step and needs K >= "
                f"{GALERKIN_MIN_QUADRATURE}")


def positive_int(text: str, bits: int = 64) -> int:
    """An integer >= 1 that fits the signed C integer of `bits` it lands in (a long: 64, an
    int: 32), so that nothing wraps on the way."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    if value >= 2 ** (bits - 1):
        raise argparse.ArgumentTypeError(f"must be below 2^{bits - 1}, got {value}")
    return value


def check_samples(text: str) -> int:
    """check --samples: 1 to chaingen.studies.check.MAX_SAMPLES (the time it takes)."""
    from .studies.check import MAX_SAMPLES

    value = positive_int(text)
    if value > MAX_SAMPLES:
        raise argparse.ArgumentTypeError(
            f"must be at most {MAX_SAMPLES} (a random state takes milliseconds to 0.15 s to "
            f"check, so {MAX_SAMPLES} of them take up to hours), got {value}")
    return value


def integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None


def positive_c_int(text: str) -> int:
    """positive_int for a C int (32 bits): an int field of the Newton options."""
    return positive_int(text, 32)


def number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None


def load_command_scene(path: str | os.PathLike[str]) -> Scene | SpatialScene:
    """The scene file a command is given, planar or spatial: its kind is told by its keys
    (chaingen.scene.reader.spatial_marker: a link's `joint` table or a gravity vector), and
    the reader of that kind validates it (SceneError: one line naming file, key and value)."""
    return load_either_scene(path)


def add_scheme_options(parser: argparse.ArgumentParser,
                       order_default: str = "the scene's") -> None:
    parser.add_argument("scene", type=Path, help="scene file (TOML, see docs/scene-format.md)")
    parser.add_argument("--method", choices=METHODS,
                        help="time-stepping scheme (default: the scene's [simulation].method; "
                             f"{SPATIAL_DEFAULT_METHOD} for a spatial scene that names none)")
    # K's range is the rules' (run_settings): one message for 0 and for 21.
    parser.add_argument("--quadrature", type=integer, metavar="K",
                        help="Gauss-Legendre points for the spring terms of 'es'; at "
                             f"order {GALERKIN_ORDER}, K + 1 Gauss-Lobatto nodes of its "
                             "Galerkin step (a spatial scene's es takes K at that order "
                             "only) (default: the scene's)")
    parser.add_argument("--gradient", choices=GRADIENTS,
                        help="es's discrete gradient of the springs: exact (the energy balance "
                             "holds identically), quadrature (the K-point average alone, the "
                             "thesis's) or chain (the chain rule's, exact without quadrature) "
                             "(default: the scene's)")
    parser.add_argument("--order", type=int, choices=ORDERS,
                        help="order of the step: 2 (the scheme's), 4 or 6 (a symmetric "
                             f"composition of its steps; {ORDERS_TAKEN}) (default: "
                             f"{order_default})")


def paths(text: str) -> tuple[str, ...]:
    return tuple(path.strip() for path in text.split(",") if path.strip())


def add_parameters_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--parameters", type=paths, default=(), metavar="PATH[,PATH...]",
                        help="numbers of the scene the solver takes at run time, by key path "
                             "(e.g. springs[0].stiffness,links[1].mass), or all of them: all")


def add_newton_options(parser: argparse.ArgumentParser, *, adaptive: bool = True) -> None:
    """The Newton options of the contract, each overriding the package's default; without
    the adaptive tolerances for a command whose steps are fixed (adaptive=False)."""
    group = parser.add_argument_group("Newton options (default: the package's)")
    for field in contract.NEWTON_OPTIONS:
        if not adaptive and field.name in contract.ADAPTIVE_TOLERANCES:
            continue
        flag = "--" + field.name.replace("_", "-")
        if field.name == "reuse_jacobian":
            group.add_argument(flag, choices=JACOBIAN_CHOICES, metavar="MODE",
                               help="when dF/dz is evaluated: " + ", ".join(JACOBIAN_CHOICES))
        elif field.switch:
            group.add_argument(flag, choices=("on", "off"), help=field.comment or None)
        elif field.python_type is int:
            if field.c_type != "int":
                raise ValueError(f"{field.name}: no command-line type for C {field.c_type}")
            group.add_argument(flag, type=positive_c_int, metavar="N",
                               help=field.comment or None)
        elif field.name in contract.ADAPTIVE_TOLERANCES:
            group.add_argument(flag, type=adaptive_tolerance, metavar="X",
                               help=field.comment or None)
        else:
            group.add_argument(flag, type=functools.partial(tolerance, field=field),
                               metavar="X", help=field.comment or None)


#: reuse_jacobian on the command line: the contract's mode names, e.g. per-step.
JACOBIAN_CHOICES = {mode.name.removeprefix("JACOBIAN_").lower().replace("_", "-"): mode.value
                    for mode in contract.JACOBIAN_MODES}


def adaptive_tolerance(text: str) -> float:
    """--rtol, --atol: a number the rule of adaptive tolerances takes (solver_rules)."""
    value = number(text)
    refused = request_refusal({"rtol": value})
    if refused:
        raise argparse.ArgumentTypeError(refused.message)
    return value


def tolerance(text: str, field: contract.OptionField) -> float:
    """A double of the Newton options, in its field's range (the Python runtime's rule:
    --residual-tol and --update-atol > 0, the others >= 0; finite)."""
    value = number(text)
    refused = option_refusal(field, value)
    if refused:
        raise argparse.ArgumentTypeError(f"{refused}, got {text!r}")
    return value


def newton_overrides(args) -> dict:
    """The Newton options given on the command line, as contract field values."""
    overrides = {}
    for field in contract.NEWTON_OPTIONS:
        value = getattr(args, field.name, None)
        if value is None:
            continue
        if field.name == "reuse_jacobian":
            value = JACOBIAN_CHOICES[value]
        elif field.switch:
            value = value == "on"
        overrides[field.name] = value
    return overrides


def seed(text: str) -> int:
    """A random seed: an integer from 0 to 2^64 - 1 (numpy's generators take no other)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
    if not 0 <= value < 2 ** 64:
        raise argparse.ArgumentTypeError(f"must be between 0 and 2^64 - 1, got {value}")
    return value


def dimension(text: str) -> int:
    value = positive_int(text)
    if not 100 <= value <= 4000:
        raise argparse.ArgumentTypeError(f"must be between 100 and 4000 pixels, got {value}")
    return value
