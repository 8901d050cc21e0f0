"""What one run of `chaingen bench` does: the series, the targets, the options.

`bench_config` turns the command line's values into a checked BenchConfig; BenchError names a
bad one. VARIANTS is the one list of Newton options our schemes are run with: every row and
headline names its variant, and a new knob is one more entry there.
"""
from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import BenchError
from ...runtime import JACOBIAN_ACROSS_STEPS, NewtonOptions, Solver
from ...runtime.files import check_output_file
from ...scene import METHODS, STANDARD_SCENES, load_reference_scene

#: The report and its figures, relative to the working directory, unless --out says otherwise.
DEFAULT_OUT = "benchmarks.md"
#: The scene of the headline ratios.
HEADLINE_SCENE = "three_link_mono"
HARNESS_FLAGS = ("-O2",)


# --------------------------------------------------------------------------------------------
# What runs
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Variant:
    """Newton options our schemes are timed with: a label for the tables and the fields the
    harness sets (the contract's Newton option fields; unset fields keep the package's
    defaults)."""

    label: str
    options: dict = field(default_factory=dict)

    def newton_options(self, solver: Solver) -> NewtonOptions:
        """The same options for Solver.simulate (the error run): the package's defaults with
        this variant's fields."""
        return solver.newton_options(self.options)


#: The Newton variants every scheme is run with: the package's defaults (warm start; Newton-chord,
#: the Jacobian once a step, for "es" and "midpoint", simplified Newton for "vi") and simplified
#: Newton (the factorised Jacobian reused across iterations and steps). The knobs module
#: measures the other knobs.
#: A new knob is one more entry here.
VARIANTS = (Variant("default options", {}),
            Variant("simplified Newton", {"reuse_jacobian": JACOBIAN_ACROSS_STEPS}))

DEFAULT_DTS = (0.04, 0.02, 0.01, 0.005, 0.0025)
#: es also runs at these larger steps on the headline scene, so that its energy error can reach
#: the error of headline c (1e-10 J) from above: measured, not extrapolated.
BRACKET_DTS = (0.2, 0.1, 0.05)
#: K = 5: the quadrature error, not dt, bounds es's energy error (O(dt^2K)), so a higher K reaches
#: a given energy error at a much larger dt (headline c).
QUADRATURES = (1, 2, 3, 5)
MUJOCO_INTEGRATORS = ("Euler", "implicitfast", "RK4")
MUJOCO_DTS = (0.01, 0.005, 0.0025, 0.001, 5e-4, 2.5e-4, 1e-4)
SCIPY_TOLERANCES = (("DOP853", tuple(10.0 ** -k for k in range(4, 13))),
                    ("Radau", tuple(10.0 ** -k for k in range(4, 11))))
#: The compiled peers (chaingen.reference.compiled_peers.METHODS, named here so that the
#: config imports none of them) at DOP853's tolerances and three tighter ones; their runs take
#: milliseconds. Below 1e-12 their energy errors fall under 1e-10 J (numbalsoda's DOP853:
#: 1.0e-10 J at 1e-12, 2.4e-11 at 3e-13), so that f and g compare runs that hold both errors.
COMPILED_TOLERANCES = tuple(
    (method, SCIPY_TOLERANCES[0][1] + (3e-13, 1e-13, 3e-14))
    for method in ("numbalsoda-LSODA", "numbalsoda-DOP853", "CVODES-BDF", "CVODES-Adams"))
#: Composed steps (method, order, K): es at K = 5, where the quadrature's energy error is below
#: 1e-12 J on the reference scenes at these steps, at order 4 (its own step composed) and 6
#: (its Galerkin step composed); vi and midpoint at orders 4 and 6.
HIGHER_ORDERS = (("es", 4, 5), ("es", 6, 5), ("vi", 4, 3), ("vi", 6, 3), ("midpoint", 4, 3),
                 ("midpoint", 6, 3))
HIGHER_ORDER_DTS = (0.1, 0.05, 0.04, 0.02, 0.01)
#: Adaptive steps (method, order, K, tolerances rtol = atol), samples every ADAPTIVE_SAMPLE s
#: (a step is at most half of it).
#: es at order 2 with the scenes' own K = 3; at order 4 with K = 5 (its steps are longer).
ADAPTIVE_RUNS = (("es", 2, 3, (1e-6, 1e-8, 1e-10)), ("es", 4, 5, (1e-6, 1e-8, 1e-10)))
ADAPTIVE_SAMPLE = 0.05
SCALING_NS = (2, 3, 5, 10, 20, 50, 100)
#: (method, quadrature) of the scaling series.
SCALING_METHODS = (("es", 3), ("vi", 3), ("midpoint", 3))
#: es on both scaling chains (scenes.scaling_scene and its uneven sibling scenes.uneven_scene:
#: uneven links, COMs off the link axis), with its default gradient and with the chain rule's
#: (chain, method, quadrature, gradient); what `--uneven-only` runs.
UNEVEN_ONLY_SERIES = (("identical", "es", 3, "exact"), ("uneven", "es", 3, "exact"),
                      ("identical", "es", 3, "chain"), ("uneven", "es", 3, "chain"))
#: The scaling series: every scheme on the chain of identical links, and UNEVEN_ONLY_SERIES.
SCALING_SERIES = tuple(dict.fromkeys(
    tuple(("identical", method, quadrature, "exact") for method, quadrature in SCALING_METHODS)
    + UNEVEN_ONLY_SERIES))
#: dt of the scaling series' per-step time, and the smaller ones tried if a scheme fails at it.
SCALING_DTS = (0.01, 0.005, 0.0025)
MUJOCO_TIMED_STEPS = 20_000
#: A SciPy or compiled peer's run shorter than this (CPU s) is repeated and its median taken.
SCIPY_REPEAT_BELOW = 1.0

#: Targets of issue 6.
TARGET_RATIO_ES = 0.3          # a: es K=3 step / MuJoCo RK4 step, mono, dt = 0.01
TARGET_ENERGY_ES = 1e-11       # a: es K=3 max energy error (J)
TARGET_RATIO_VI = 0.15         # b: vi step / MuJoCo RK4 step
TARGET_EQUAL_ERROR = 1e-10     # c: the energy error (J) at which CPU times are compared
TARGET_SCIPY_OVER_ES = 100.0   # c: DOP853 CPU / es CPU at that error
TARGET_BUILD_SECONDS = 20.0    # d: generate + build at n = 20
#: d, long chains: generate + build seconds of each scheme at n (the scaling chain).
TARGET_SCALING_BUILD = ((20, TARGET_BUILD_SECONDS), (50, 60.0))
#: d, long chains: step / MuJoCo RK4 step on the scaling chain at dt = 0.01 s, (scheme, n,
#: target): es at most half of RK4's at n = 20 and 50, vi and midpoint at most RK4's at n = 20.
TARGET_SCALING_RATIOS = (("es K=3", 20, 0.5), ("es K=3", 50, 0.5), ("vi", 20, 1.0),
                         ("midpoint", 20, 1.0))
#: d, issue 32 f: the same ratio on the uneven scaling chain (scenes.uneven_scene).
TARGET_UNEVEN_RATIOS = (("es K=3", 20, 0.5),)
TARGET_STEP_OVER_EVALUATION = 2.5   # e: es K=3 step / one residual-and-Jacobian evaluation
HEADLINE_DT = 0.01
#: f, g: (trajectory error at EARLY_T [rad], energy error [J]) that a run must hold both of;
#: the cheapest such run of ours against the cheapest of a peer's.
HELD_ERRORS = ((1e-6, 1e-10), (1e-8, 1e-10))
#: f, g: our best CPU / the peer's CPU at the held errors (ours at least as fast).
TARGET_OURS_OVER_PEER = 1.0
#: i: adaptive es (K = ADAPTIVE_K, order 2) at rtol = atol = ADAPTIVE_RTOL on ADAPTIVE_SCENE:
#: its trajectory error at EARLY_T over that of fixed steps of the same CPU, and its energy error.
ADAPTIVE_SCENE = "three_link_multi"
ADAPTIVE_K = 3
#: Fixed es steps below DEFAULT_DTS on ADAPTIVE_SCENE, so that their CPU reaches the adaptive
#: run's and headline i interpolates instead of extrapolating.
ADAPTIVE_BRACKET_DTS = (0.00125, 0.000625)
ADAPTIVE_RTOL = 1e-8
TARGET_ADAPTIVE_OVER_FIXED = 10.0
TARGET_ADAPTIVE_ENERGY = 1e-12
#: h: trajectory errors at EARLY_T [rad] at which every peer's CPU is compared with our best
#: (no target).
TRAJECTORY_LEVELS = (1e-6, 1e-8)
#: The early time of the second trajectory error: over the standard run's 50 s the reference
#: scenes amplify differences (1e-12 rad at t = 0 becomes 1e-5 to 1e-4 at 50 s), so only an
#: error taken this early measures a method's accuracy (the reference is good to 1e-14 there).
EARLY_T = 3.0
HEADLINE_N = 20


#: The stiff chain's work-precision (issue 32 g, the stiff module): scaling_scene(n) with every
#: spring at STIFF_STIFFNESS, STIFF_T_END s from its initial state, ours against the compiled
#: peers and MuJoCo; the trajectory error at STIFF_T_END against SciPy DOP853 at
#: rtol = atol = STIFF_REFERENCE_RTOL.
STIFF_N = 10
STIFF_STIFFNESS = 2e4          # N/m, mono- and multi-articular springs alike
STIFF_T_END = 0.2
STIFF_REFERENCE_RTOL = 1e-13
#: Ours at fixed steps (method, order, K, gradient, dts): es with the exact discrete gradient
#: (the default) and with the quadrature alone, vi and midpoint, at orders 2 and 4.
STIFF_ORDER2_DTS = (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4)
STIFF_ORDER4_DTS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
STIFF_SCHEMES = (("es", 2, 3, "exact", STIFF_ORDER2_DTS),
                 ("es", 2, 3, "quadrature", (2e-3, 1e-3, 5e-4)),
                 ("vi", 2, 3, "exact", STIFF_ORDER2_DTS),
                 ("midpoint", 2, 3, "exact", STIFF_ORDER2_DTS),
                 ("es", 4, 5, "exact", STIFF_ORDER4_DTS),
                 ("es", 4, 5, "quadrature", (5e-3, 2e-3, 1e-3)),
                 ("vi", 4, 3, "exact", STIFF_ORDER4_DTS),
                 ("midpoint", 4, 3, "exact", STIFF_ORDER4_DTS))
#: Adaptive es (method, order, K, tolerances rtol = atol), samples every STIFF_ADAPTIVE_SAMPLE s.
STIFF_ADAPTIVE = (("es", 2, 3, (1e-6, 1e-8, 1e-10, 1e-12)),)
STIFF_ADAPTIVE_SAMPLE = 0.01
#: The compiled peers at these tolerances (rtol = atol); below 1e-12 they would be measured
#: against a reference that is no tighter than themselves.
STIFF_PEER_TOLERANCES = tuple(10.0 ** -k for k in range(4, 13))
STIFF_MUJOCO = (("RK4", (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5)),
                ("implicitfast", (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5)))
#: The compiled peers' energy error is taken over samples this far apart (s), from a second,
#: untimed run (their timed run samples every 0.01 s, as on the reference scenes).
STIFF_ENERGY_SAMPLE = 2.5e-4
#: The summary's levels (trajectory error [rad], energy error relative to the energy), None
#: where a level does not ask for that error: the cheapest measured run of ours and of each
#: peer family holding both.
STIFF_LEVELS = ((1e-3, None), (1e-5, None), (1e-7, None), (1e-9, None),
                (None, 1e-6), (None, 1e-9), (None, 1e-12), (1e-5, 1e-12))


@dataclass(frozen=True)
class StiffSettings:
    """What the stiff chain's part runs (the STIFF_* constants, or a smaller quick set)."""

    n: int
    stiffness: float
    t_end: float
    reference_rtol: float
    schemes: tuple[tuple[str, int, int, str, tuple[float, ...]], ...]
    adaptive: tuple[tuple[str, int, int, tuple[float, ...]], ...]
    adaptive_sample: float
    peer_tolerances: tuple[float, ...]
    mujoco: tuple[tuple[str, tuple[float, ...]], ...]
    energy_sample: float
    levels: tuple[tuple[float | None, float | None], ...] = STIFF_LEVELS


STIFF_SETTINGS = StiffSettings(
    n=STIFF_N, stiffness=STIFF_STIFFNESS, t_end=STIFF_T_END,
    reference_rtol=STIFF_REFERENCE_RTOL, schemes=STIFF_SCHEMES, adaptive=STIFF_ADAPTIVE,
    adaptive_sample=STIFF_ADAPTIVE_SAMPLE, peer_tolerances=STIFF_PEER_TOLERANCES,
    mujoco=STIFF_MUJOCO, energy_sample=STIFF_ENERGY_SAMPLE)
#: The quick form: three links (the SciPy peer's ODE of ten links takes some 100 s to derive
#: and build), one run of each kind.
STIFF_QUICK_SETTINGS = StiffSettings(
    n=3, stiffness=STIFF_STIFFNESS, t_end=STIFF_T_END, reference_rtol=STIFF_REFERENCE_RTOL,
    schemes=(("es", 2, 3, "exact", (2e-3, 1e-3)), ("es", 2, 3, "quadrature", (1e-3,)),
             ("vi", 2, 3, "exact", (1e-3,)), ("midpoint", 4, 3, "exact", (2e-3,))),
    adaptive=(("es", 2, 3, (1e-6,)),), adaptive_sample=STIFF_ADAPTIVE_SAMPLE,
    peer_tolerances=(1e-6, 1e-8), mujoco=(("RK4", (5e-4,)),), energy_sample=1e-3)



@dataclass(frozen=True)
class BenchConfig:
    """Everything one run of the benchmark does; `bench_config` makes and checks it."""

    quick: bool
    scenes: tuple[str, ...]
    t_end: float | None                  # None: each scene's own [simulation].t_end
    dts: tuple[float, ...]
    quadratures: tuple[int, ...]
    methods: tuple[str, ...]
    mujoco_integrators: tuple[str, ...]
    mujoco_dts: tuple[float, ...]
    scipy_tolerances: tuple[tuple[str, tuple[float, ...]], ...]
    compiled_tolerances: tuple[tuple[str, tuple[float, ...]], ...]
    higher_orders: tuple[tuple[str, int, int], ...]
    higher_order_dts: tuple[float, ...]
    adaptive_runs: tuple[tuple[str, int, int, tuple[float, ...]], ...]
    scaling_ns: tuple[int, ...]
    scaling_methods: tuple[tuple[str, int], ...]
    scaling_series: tuple[tuple[str, str, int, str], ...]   # (chain, method, K, gradient)
    timeout: float
    repeats: int                         # harness and MuJoCo timing repeats
    scipy_repeats: int
    scaling_steps: int                   # steps timed per repeat in the scaling series
    run_reference: bool
    run_scaling: bool
    run_sweep: bool                      # part 4's sweeps (the parameter timings always run)
    run_stiff: bool                      # the stiff chain's work-precision
    stiff_only: bool                     # that part alone, its section written in place
    uneven_only: bool                    # es on both scaling chains alone, written in place
    stiff: StiffSettings
    out: Path
    figures: Path
    command: str
    spatial_only: bool = False           # the spatial arm alone, its section written in place


def _parse_list(text: str, option: str, kind):
    values = []
    for item in text.split(","):
        item = item.strip()
        what, example = ("an integer", "2,3,5") if kind is int else ("a number", "0.02,0.01")
        try:
            value = kind(item)
        except ValueError:
            raise BenchError(f"{option}: {item!r} is not {what} (give a comma-separated list, "
                             f"e.g. {option} {example})") from None
        values.append(value)
    return tuple(values)


def divides_evenly(dt: float, t_end: float) -> bool:
    steps = round(t_end / dt)
    return steps >= 1 and abs(steps * dt - t_end) <= 1e-9 * t_end


def _check_divides(dt: float, t_end: float, option: str) -> None:
    if not divides_evenly(dt, t_end):
        raise BenchError(f"{option}: dt = {dt!r} s does not divide the run's t_end = {t_end:g} s "
                         "(the trajectory error is taken at t_end)")


#: The stiff chain's figure: bench_<this>.png.
STIFF_FIGURE = "stiff_chain"

#: The first line of every report, and the mark a quick run's report carries.
REPORT_TITLE = "# Benchmarks: speed against accuracy"
QUICK_MARK = "**Quick mode**"


def is_full_report(path: Path) -> bool:
    """Whether `path` is the report of a full `chaingen bench` run (a quick run's carries
    QUICK_MARK in its opening paragraph)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as stream:
            head = stream.read(4096)
    except OSError:
        return False
    return head.startswith(REPORT_TITLE) and QUICK_MARK not in head


def bench_config(*, quick: bool = False, dts: str | None = None, scaling_n: str | None = None,
                 timeout: float = 300.0, skip_scaling: bool = False,
                 skip_reference: bool = False, skip_sweep: bool = False,
                 skip_stiff: bool = False, stiff_only: bool = False,
                 uneven_only: bool = False, spatial_only: bool = False,
                 out: Path | None = None, figures: Path | None = None) -> BenchConfig:
    """The run's settings from the command line's values; BenchError names a bad one.
    stiff_only: the stiff chain's part alone, its section written into `out` in place (the
    rest of an existing report kept). uneven_only: es on the two scaling chains alone (at the
    scaling series' n), the uneven chain's subsection of the scaling section written into
    `out` in place. spatial_only: the spatial arm's part alone (spatial module), its section
    written into `out` in place."""
    if spatial_only and (stiff_only or uneven_only):
        raise BenchError("--spatial-only runs one part alone: it goes with neither "
                         "--stiff-only nor --uneven-only")
    if stiff_only and skip_stiff:
        raise BenchError("--stiff-only and --skip-stiff: the one runs only what the other "
                         "leaves out; give one of them")
    if uneven_only and (stiff_only or skip_scaling):
        raise BenchError("--uneven-only runs a part of the scaling series alone: it goes with "
                         "neither --stiff-only nor --skip-scaling")
    command_skips = (skip_scaling, skip_reference, skip_sweep)
    if stiff_only:
        skip_scaling = skip_reference = skip_sweep = True
    if uneven_only:
        skip_reference = skip_sweep = skip_stiff = True
    if spatial_only:
        skip_scaling = skip_reference = skip_sweep = skip_stiff = True
    if not (math.isfinite(timeout) and timeout > 0):
        raise BenchError(f"--timeout: must be > 0 seconds and finite, got {timeout}")
    for module in ("mujoco", "scipy", "matplotlib") + (
            () if skip_sweep else ("pyarrow", "pandas", "xarray", "zarr", "distributed")):
        if importlib.util.find_spec(module) is None:
            raise BenchError(f"chaingen bench needs {module}, which is not installed "
                             "(pip install -e '.[test]'; --skip-sweep runs without the sweep "
                             "extra)")
    scenes = (HEADLINE_SCENE,) if quick else STANDARD_SCENES
    t_end = 2.0 if quick else None
    if dts is None:
        dt_values = (0.02, 0.01) if quick else DEFAULT_DTS
    else:
        dt_values = _parse_list(dts, "--dts", float)
        for dt in dt_values:
            if not (math.isfinite(dt) and dt > 0):
                raise BenchError(f"--dts: every dt must be > 0 and finite, got {dt!r}")
    if not skip_reference:
        for name in scenes:
            run_end = t_end or load_reference_scene(name).simulation.t_end
            for dt in dt_values:
                _check_divides(dt, run_end, "--dts")
    if scaling_n is None:
        ns = (2, 3) if quick else SCALING_NS
    else:
        ns = _parse_list(scaling_n, "--scaling-n", int)
        for n in ns:
            if not 2 <= n <= 100:
                raise BenchError(f"--scaling-n: every n must be between 2 and 100 (a "
                                 f"multi-articular spring needs two joints), got {n}")
    out_default = out is None
    out = Path(out) if out is not None else Path(DEFAULT_OUT)
    check_output_file(out, "--out")
    if quick and is_full_report(out):
        raise BenchError(f"--out: {out} is the report of a full run; --quick (a smoke test) "
                         "does not replace it: give another --out")
    figures_default = figures is None
    figures = Path(figures) if figures is not None else out.parent / "figures"
    if figures.exists() and not figures.is_dir():
        raise BenchError(f"--figures: {figures} exists and is not a directory")
    if not figures.exists() and not figures.parent.is_dir():
        raise BenchError(f"--figures: directory {figures.parent} does not exist")
    if figures.is_dir():   # the figures it will write, checked as every output is
        names = ((STIFF_FIGURE,) if stiff_only else () if uneven_only or spatial_only else
                 (*scenes, "scaling") + (() if skip_stiff else (STIFF_FIGURE,)))
        for name in names:
            check_output_file(figures / f"bench_{name}.png", "--figures", [out])

    command = ["chaingen", "bench"]
    command += ["--quick"] if quick else []
    command += ["--dts", dts] if dts is not None else []
    command += ["--scaling-n", scaling_n] if scaling_n is not None else []
    command += ["--stiff-only"] if stiff_only else []
    command += ["--uneven-only"] if uneven_only else []
    command += ["--spatial-only"] if spatial_only else []
    command += ["--skip-scaling"] if command_skips[0] else []
    command += ["--skip-reference"] if command_skips[1] else []
    command += ["--skip-sweep"] if command_skips[2] else []
    command += ["--skip-stiff"] if skip_stiff and not (uneven_only or spatial_only) else []
    command += ["--timeout", f"{timeout:g}"] if timeout != 300.0 else []
    command += [] if out_default else ["--out", str(out)]
    command += [] if figures_default else ["--figures", str(figures)]
    return BenchConfig(
        quick=quick, scenes=scenes, t_end=t_end, dts=dt_values,
        quadratures=(3,) if quick else QUADRATURES, methods=METHODS,
        mujoco_integrators=("Euler", "RK4") if quick else MUJOCO_INTEGRATORS,
        mujoco_dts=(0.01, 0.001) if quick else MUJOCO_DTS,
        scipy_tolerances=((("DOP853", (1e-6, 1e-10)), ("Radau", (1e-6,))) if quick
                          else SCIPY_TOLERANCES),
        compiled_tolerances=(tuple((method, (1e-6, 1e-10)) for method, _ in COMPILED_TOLERANCES)
                             if quick else COMPILED_TOLERANCES),
        higher_orders=(("es", 4, 5), ("vi", 6, 3)) if quick else HIGHER_ORDERS,
        higher_order_dts=(0.1, 0.05) if quick else HIGHER_ORDER_DTS,
        adaptive_runs=(("es", 2, 3, (1e-6,)),) if quick else ADAPTIVE_RUNS,
        scaling_ns=ns, scaling_methods=SCALING_METHODS,
        scaling_series=UNEVEN_ONLY_SERIES if uneven_only else SCALING_SERIES,
        timeout=float(timeout),
        repeats=3 if quick else 7, scipy_repeats=1 if quick else 3,
        scaling_steps=200 if quick else 1000,
        run_reference=not skip_reference, run_scaling=not skip_scaling,
        run_sweep=not skip_sweep, run_stiff=not skip_stiff, stiff_only=stiff_only,
        uneven_only=uneven_only,
        stiff=STIFF_QUICK_SETTINGS if quick else STIFF_SETTINGS,
        out=out, figures=figures, command=" ".join(command), spatial_only=spatial_only)


def steps(t_end: float, dt: float) -> int:
    return round(t_end / dt)
