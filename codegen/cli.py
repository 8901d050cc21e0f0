"""The `chaingen` command: generate C solvers for a scene, simulate with them, check them."""
from __future__ import annotations

import argparse
import errno
import os
import sys
from pathlib import Path

from .arguments import (
    ORDERS_TAKEN,
    add_newton_options,
    add_parameters_option,
    add_scheme_options,
    check_samples,
    dimension,
    load_command_scene,
    newton_overrides,
    number,
    positive_int,
    seed,
)
from .errors import (
    ChaingenError,
    NewtonError,
    RunFailedError,
    SceneError,
    SettingsError,
    UnsupportedSceneError,
)
from .runtime.files import check_output_directory, check_output_file, reported_write
from .scene.shipped import scene_file
from .spatial import SpatialScene
from .spatial.urdf import add_import_arguments, command_import
from .version import VERSION
from .view_commands import command_animate, command_plot

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
#: OSErrors of a path no file can have: bad input wherever they are met (exit status 2).
PATH_ERRORS = (errno.ENAMETOOLONG, errno.ELOOP)


def parser() -> argparse.ArgumentParser:
    main = argparse.ArgumentParser(
        prog="chaingen",
        description="Structure-preserving solvers for elastic robot arms, planar and spatial: "
                    "SymPy derives the model, CasADi generates C, and the C solver simulates.")
    main.add_argument("--version", action="version", version=f"chaingen {VERSION}")
    main.add_argument("--debug", action="store_true",
                      help="show the traceback of an unexpected error (or CHAINGEN_DEBUG=1)")
    main.add_argument("-q", "--quiet", action="store_true",
                      help="no progress bars (they appear only on a terminal, never in CI)")
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                       help="no progress bars (they appear only on a terminal, never in CI)")
    commands = main.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, **kwargs):   # every command also takes --quiet after its name
        return commands.add_parser(name, parents=[quiet], **kwargs)

    generate = command("generate", help="write the C package of a scene's solver")
    add_scheme_options(generate)
    generate.add_argument("-o", "--output", type=Path, metavar="DIR",
                          help="package directory (default: ./<scene>_<method>)")
    generate.add_argument("--no-sensitivities", dest="sensitivities", action="store_false",
                          help="leave out step_sensitivities (smaller code, faster build)")
    add_parameters_option(generate)

    export = command("export", help="write a scene as a MuJoCo model (MJCF)")
    export.add_argument("scene", type=Path, help="scene file (TOML, see docs/scene-format.md)")
    export.add_argument("--mjcf", type=Path, required=True, metavar="OUT.xml",
                        help="the MuJoCo XML to write")
    export.add_argument("--dt", type=number, help="its time step in s (default: the scene's)")
    export.add_argument("--integrator", default="RK4",
                        help="MuJoCo's integrator: RK4 (default), Euler, implicit, implicitfast")

    add_import_arguments(command("import", help="write the scene of a robot's chain from a URDF"))
    simulate = command("simulate", help="simulate a scene with a generated solver")
    add_scheme_options(simulate)
    add_newton_options(simulate)
    simulate.add_argument("--dt", type=number, help="step in s (default: the scene's)")
    simulate.add_argument("--t-end", type=number, help="duration in s (default: the scene's)")
    simulate.add_argument("--every", type=positive_int, default=1, metavar="N",
                          help="write every N-th step (t = 0 always included; default 1)")
    simulate.add_argument("--out", type=Path, metavar="FILE.csv",
                          help="write the trajectory file (scene-format.md) and its metadata "
                               "FILE.csv.json")
    simulate.add_argument("--plot", nargs="?", const="", metavar="FILE.png",
                          help="also draw the run (chaingen plot); default file: beside --out, "
                               "else ./<scene>_<method>.png")

    plot = command(
        "plot", help="figures of trajectory files (angles, energy and constraint errors) or of "
                     "a sweep's metric")
    plot.add_argument("trajectories", type=Path, nargs="+", metavar="TRAJ.csv|OUT",
                      help="trajectory files (several overlay their error curves), or a sweep's "
                           "result directory")
    plot.add_argument("-o", "--output", type=Path, metavar="DIR|FILE.png",
                      help="a .png file, or a directory (created; default: beside the first "
                           "trajectory)")
    plot.add_argument("--metric", metavar="METRIC",
                      help="for a sweep: the column of runs.parquet to draw, or "
                           "amplitude_phi<i>")

    sweep = command("sweep", help="many runs of a scene with its numbers varied, one compiled "
                                  "solver (docs/sweeps.md)")
    sweep.add_argument("spec", type=Path, metavar="SPEC.toml",
                       help="the sweep spec (docs/sweep-format.md)")
    sweep.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                       help="the result directory (a rerun of the same spec resumes it)")
    engine = sweep.add_mutually_exclusive_group()
    engine.add_argument("--dask-local", type=positive_int, metavar="N",
                        help="run on a Dask LocalCluster of N worker processes")
    engine.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on the Dask cluster at ADDRESS (tcp://host:8786)")
    engine.add_argument("--jobs", type=positive_int, metavar="N",
                        help="local engine: run on N threads (default: one per core)")
    sweep.add_argument("--plot", metavar="METRIC",
                       help="draw METRIC against the axes into OUT/METRIC.png")

    animate = command(
        "animate", help="animate the chain and its springs (GIF, or MP4 with ffmpeg); a "
                        "spatial scene in a front (x-z) and a top (x-y) view")
    add_scheme_options(animate)
    add_newton_options(animate)
    animate.add_argument("trajectory", type=Path, nargs="?", metavar="TRAJ.csv",
                         help="trajectory of the scene (default: simulate the scene first)")
    animate.add_argument("-o", "--output", type=Path, required=True, metavar="FILE.gif",
                         help="the animation: .gif (Pillow) or .mp4 (needs ffmpeg)")
    animate.add_argument("--dt", type=number, help="step in s when simulating (default: the "
                                                    "scene's)")
    animate.add_argument("--t-end", type=number,
                         help="animate up to this time in s (default: the whole run)")
    animate.add_argument("--fps", type=number,
                         help="frames per second, 0.01 to 100 (default 25, in real time)")
    animate.add_argument("--every", type=positive_int, metavar="N",
                         help="draw every N-th sample (default: real time at --fps)")
    animate.add_argument("--size", type=dimension, default=480, metavar="PIXELS",
                         help="width and height of the frames; a spatial scene's are as "
                              "high and hold two views side by side (default 480; 100 to "
                              "4000, 200 at least for a scene with springs)")

    check = command(
        "check", help="compare the generated functions with finite differences and SymPy")
    add_scheme_options(check)
    add_parameters_option(check)
    check.add_argument("--samples", type=check_samples, default=5, metavar="N",
                       help="random states to check at, 1 to 100000 (default 5)")
    check.add_argument("--seed", type=seed, default=0,
                       help="random seed, 0 to 2^64 - 1 (default 0)")
    check.add_argument("--dt", type=number, help="step in s (default: the scene's)")

    order = command(
        "order", help="time-step study: energy, angle and rate error per dt, fitted orders",
        description="The time-step study (docs/model.md, section 8) of every order of the step "
                    f"({ORDERS_TAKEN}), each on its own step sizes, then a summary of the fitted "
                    "orders; with --order N only order N. Its steps are fixed: it takes no "
                    "adaptive tolerances.")
    add_scheme_options(order, order_default="every order the method takes")
    add_newton_options(order, adaptive=False)
    for flag in ("--rtol", "--atol"):     # not offered; given, they get the reason below
        order.add_argument(flag, type=number, help=argparse.SUPPRESS)
    order.add_argument("--t-end", type=number, default=10.0,
                       help="duration of each run in s (default 10)")
    order.add_argument("--plot", type=Path, metavar="FILE.png",
                       help="write the log-log order plot (needs matplotlib)")

    bench = command(
        "bench", help="speed/accuracy benchmark against MuJoCo and SciPy (docs/benchmarks.md)")
    bench.add_argument("--quick", action="store_true",
                       help="a smoke run of about a minute: one scene, short runs, n = 2, 3")
    bench.add_argument("--out", type=Path, metavar="FILE.md",
                       help="the document to write (default: ./benchmarks.md)")
    bench.add_argument("--figures", type=Path, metavar="DIR",
                       help="directory of the figures (default: figures/ next to --out)")
    bench.add_argument("--dts", metavar="DT,DT,...",
                       help="our schemes' steps in s (default 0.04,0.02,0.01,0.005,0.0025)")
    bench.add_argument("--scaling-n", metavar="N,N,...",
                       help="chain lengths of the scaling series (default 2,3,5,10,20,50,100)")
    bench.add_argument("--skip-scaling", action="store_true", help="leave out the scaling series")
    bench.add_argument("--skip-reference", action="store_true",
                       help="leave out the reference scenes")
    bench.add_argument("--skip-sweep", action="store_true",
                       help="leave out the sweeps of the studies part (no sweep extra needed)")
    bench.add_argument("--skip-stiff", action="store_true",
                       help="leave out the stiff chain's work-precision")
    bench.add_argument("--stiff-only", action="store_true",
                       help="run the stiff chain's work-precision alone and write its section "
                            "into --out in place (the rest of the report kept)")
    bench.add_argument("--uneven-only", action="store_true",
                       help="run es on the scaling chain and on its uneven sibling alone and "
                            "write the uneven chain's subsection of the scaling section into "
                            "--out in place (the rest of the report kept)")
    bench.add_argument("--spatial-only", action="store_true", help="time the spatial Panda "
                       "alone and write its section into --out in place (issue 33 d)")
    bench.add_argument("--timeout", type=number, default=300.0, metavar="SECONDS",
                       help="limit of generate + build per scheme and n (default 300)")
    return main


def command_generate(args) -> int:
    from .simulation import run_settings

    scene = load_command_scene(args.scene)
    settings = run_settings(scene, method=args.method,
                            quadrature=args.quadrature, order=args.order,
                            gradient=args.gradient, source=str(args.scene))
    # The generation stage (SymPy, CasADi) is imported once the input is known to be good.
    from .generate.package import (
        check_package_target,
        generate_package,
        package_prefix,
        write_package,
    )

    target = args.output or Path(package_prefix(scene, settings.method))
    check_output_directory(target, "-o", [args.scene])
    check_package_target(target)
    package = generate_package(settings.solver_spec(scene, sensitivities=args.sensitivities,
                                                     parameters=args.parameters))
    directory = write_package(package, target)
    print(f"wrote {directory}/: {', '.join(package.files)}")
    return 0


def command_export(args) -> int:
    from .reference.mjcf import MUJOCO_INTEGRATORS, mjcf_from_scene
    from .reference.spatial_mjcf import spatial_mjcf_from_scene
    from .runtime.files import write_text

    scene = load_command_scene(args.scene)
    spatial = isinstance(scene, SpatialScene)
    dt = scene.simulation.dt if args.dt is None else args.dt
    if not (dt > 0.0 and dt < float("inf")):
        raise SettingsError(f"--dt: must be > 0 s and finite, got {dt!r}")
    if args.integrator not in MUJOCO_INTEGRATORS:
        raise SettingsError(f"--integrator: must be one of {', '.join(MUJOCO_INTEGRATORS)}, "
                            f"got {args.integrator!r}")
    check_output_file(args.mjcf, "--mjcf", [args.scene])
    writer = spatial_mjcf_from_scene if spatial else mjcf_from_scene
    try:
        text = writer(scene, dt=dt, integrator=args.integrator, export=True)
    except ValueError as error:               # what MuJoCo cannot represent (J = 0)
        raise SettingsError(f"{args.scene}: {error}") from None
    with reported_write(args.mjcf, "the MJCF"):
        write_text(args.mjcf, text)
    actuated = scene.actuated if spatial else scene.actuated_joints
    motors = f", motors on joints {list(actuated)}" if actuated else ""
    # MJCF has no counterpart of a [control] law: the file is the plant, and says so here.
    plant = ("; the plant only: the scene's [control] law is not in the MJCF (drive its motors "
             "with it yourself)" if getattr(scene, "control", None) is not None else "")
    print(f"wrote {args.mjcf}: {scene.n} links, {len(scene.springs)} spring tendons{motors}, "
          f"dt {dt:g} s, {args.integrator}{plant}")
    return 0


def command_check(args) -> int:
    from .generate.package import render_package
    from .runtime import Solver
    from .simulation import run_settings
    from .studies.check import check_solver
    from .symbolic.schemes import build_scheme

    scene = load_command_scene(args.scene)
    settings = run_settings(scene, method=args.method,
                            quadrature=args.quadrature, dt=args.dt, order=args.order,
                            gradient=args.gradient, source=str(args.scene))
    scheme = build_scheme(settings.solver_spec(scene, parameters=args.parameters))
    solver = Solver.from_files(render_package(scheme, sensitivities=True).files)
    try:
        report = check_solver(scheme, solver, samples=args.samples, seed=args.seed,
                              dt=settings.dt)
    except NewtonError as error:   # a step the check compares failed: say which dt, and why
        raise RunFailedError(f"check: a step of dt = {settings.dt:g} s from a random state "
                             f"near the scene's initial one failed, so nothing was compared: "
                             f"{error}; check at a dt the scene runs with (--dt)") from None
    print(report.table())
    return 0 if report.passed else EXIT_FAILED


def command_order(args) -> int:
    from .simulation import run_settings
    from .studies.order import (
        SAMPLE_INTERVAL,
        allowed_orders,
        format_summary,
        format_table,
        order_studies,
    )
    from .views.order_plot import plot_order

    scene = load_command_scene(args.scene)
    # Without --order every order the method takes runs, whatever the scene's simulation.order.
    settings = run_settings(scene, method=args.method,
                            quadrature=args.quadrature,
                            t_end=args.t_end, order=args.order or 2, gradient=args.gradient,
                            source=str(args.scene))
    samples = round(settings.t_end / SAMPLE_INTERVAL)    # the study compares its runs there
    if samples < 1 or abs(samples * SAMPLE_INTERVAL - settings.t_end) > 1e-9 * settings.t_end:
        raise SettingsError(f"--t-end: must be a whole multiple of the study's sample interval, "
                            f"{SAMPLE_INTERVAL:g} s, got {settings.t_end:g}")
    if args.plot is not None:   # before the study: the plot needs matplotlib
        from .views.figure import require_matplotlib
        require_matplotlib("order --plot")
        check_output_file(args.plot, "--plot", [args.scene])
    overrides = newton_overrides(args)
    if args.rtol is not None or args.atol is not None:
        raise SettingsError("--rtol/--atol: chaingen order fits the error of fixed steps; "
                            "leave out the adaptive tolerances")
    orders = (args.order,) if args.order is not None else allowed_orders(settings.method, scene)
    studies = order_studies(scene, settings.method, settings.quadrature, orders=orders,
                            t_end=settings.t_end, overrides=overrides,
                            gradient=settings.gradient)
    print("\n\n".join(format_table(study) for study in studies))
    if len(studies) > 1:
        print()
        print(format_summary(studies))
    if args.plot is not None:
        print(f"plot: {plot_order(studies, args.plot)}")
    return 0


def command_bench(args) -> int:
    from .studies.bench import bench_config, run_bench
    from .views import bench_figures

    config = bench_config(quick=args.quick, dts=args.dts, scaling_n=args.scaling_n,
                          skip_reference=args.skip_reference, skip_scaling=args.skip_scaling,
                          skip_sweep=args.skip_sweep, spatial_only=args.spatial_only, out=args.out,
                          skip_stiff=args.skip_stiff, uneven_only=args.uneven_only,
                          stiff_only=args.stiff_only, timeout=args.timeout, figures=args.figures)
    run_bench(config, figures=bench_figures)
    return 0


def command_simulate(args) -> int:
    from .runtime import write_trajectory
    from .runtime.trajectory import metadata_path
    from .simulation import run_settings, simulate_scene
    from .views.run_summary import run_summary

    scene = load_command_scene(args.scene)
    settings = run_settings(scene, method=args.method,
                            quadrature=args.quadrature, dt=args.dt, t_end=args.t_end,
                            every=args.every, order=args.order,
                            gradient=args.gradient, rtol=args.rtol, atol=args.atol,
                            source=str(args.scene))
    figure = None
    if args.plot is not None:   # before anything is written: the figure needs matplotlib
        from .views.figure import require_matplotlib
        require_matplotlib("simulate --plot")
    if args.out is not None:
        check_output_file(args.out, "--out", [args.scene])
        check_output_file(metadata_path(args.out), "--out", [args.scene])
    if args.plot is not None:
        from .views.plots import check_png_path
        figure = check_png_path(Path(args.plot) if args.plot else (
            args.out.with_suffix(".png") if args.out is not None
            else Path(f"{args.scene.stem}_{settings.method}.png")), "--plot")
        check_output_file(figure, "--plot", [args.scene] + (
            [args.out, metadata_path(args.out)] if args.out else []))
    options = newton_overrides(args)
    try:
        result = simulate_scene(scene, settings, options=options)
    except NewtonError as error:
        print(f"chaingen: error: simulation of {args.scene} failed: {error}; no trajectory "
              "written", file=sys.stderr)
        return EXIT_FAILED
    if args.out is not None:
        with reported_write(args.out, "the trajectory"):
            write_trajectory(result, args.out)
    print(run_summary(result, settings, args.out))
    if figure is not None:
        from .views.plots import plot_result
        print(f"  figure                 {plot_result(result, figure)}")
    return 0


def command_sweep(args) -> int:
    import time

    from .studies.sweep import load_spec, require_extra, run_sweep

    require_extra()
    spec = load_spec(args.spec)
    if args.plot:
        from .views.sweep_plot import check_metric
        check_metric(args.plot, spec.scene.n, [axis.path for axis in spec.axes],
                     spec.every > 0)
    started = time.perf_counter()
    outcome = run_sweep(spec, args.output, engine="local" if not (args.dask_local
                                                                  or args.scheduler)
                        else "dask", scheduler=args.scheduler, dask_local=args.dask_local,
                        workers=args.jobs)
    import pandas as pd

    runs = pd.read_parquet(outcome.out / "runs.parquet")
    failed = int((runs["status"] != "ok").sum())
    print(f"{spec.scene.name}: {spec.method}, {outcome.runs} runs ({outcome.computed} computed "
          f"now), {failed} failed, solver {outcome.build_hash} (generate and build "
          f"{outcome.generate_seconds:.1f} s), {time.perf_counter() - started:.1f} s in all")
    print(f"  results                {outcome.out}")
    if args.plot:
        from .views.sweep_plot import plot_sweep
        print(f"  figure                 {plot_sweep(outcome.out, args.plot)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """The command line. Every error a user can cause is one line on stderr and exit status 2
    (bad input) or 1 (a run that failed); Ctrl-C exits with 130; an unexpected error is one
    line too, with the way to its traceback (--debug or CHAINGEN_DEBUG=1 shows it)."""
    args = parser().parse_args(argv)
    from .progress import quiet, set_quiet
    before = quiet()
    set_quiet(args.quiet)
    try:      # --quiet holds for this command only (main may run in a longer process)
        return _run(args)
    finally:
        set_quiet(before)


def _run(args) -> int:
    debug = args.debug or os.environ.get("CHAINGEN_DEBUG", "") not in ("", "0")
    handlers = {"generate": command_generate, "simulate": command_simulate,
                "check": command_check, "order": command_order, "bench": command_bench,
                "plot": command_plot, "animate": command_animate, "sweep": command_sweep,
                "export": command_export, "import": command_import}
    try:
        if getattr(args, "scene", None) is not None:
            args.scene = scene_file(args.scene)    # a shipped scene's name: its installed file
        return handlers[args.command](args)
    except UnsupportedSceneError as error:   # a valid scene that the chosen scheme cannot take
        prefix = "" if isinstance(error, SceneError) else f"{getattr(args, 'scene', '')}: "
        return _error(f"{prefix}{error}", EXIT_BAD_INPUT)   # a SceneError names its file
    except ChaingenError as error:
        if debug and getattr(error, "details", None):
            print(error.details, file=sys.stderr)
        return _error(str(error), error.exit_status)
    except KeyboardInterrupt:
        print("chaingen: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`chaingen ... | head`): nothing more to say.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILED
    except OSError as error:
        if error.errno not in PATH_ERRORS:
            if debug:
                raise
            return _unexpected(error)
        # A path no file can have (a name too long, a loop of links), met where it is read
        # or checked: bad input, wherever on the command line or in a file it was given.
        name = str(error.filename)
        name = name if len(name) <= 80 else name[:77] + "..."
        return _error(f"{name}: {error.strerror}", EXIT_BAD_INPUT)
    except RecursionError:
        if debug:
            raise
        return _error("input nested too deeply to process", EXIT_BAD_INPUT)
    except Exception as error:
        if debug:
            raise
        return _unexpected(error)


def _unexpected(error: BaseException) -> int:
    return _error(f"internal error: {type(error).__name__}: {error} (run again with "
                  "--debug or CHAINGEN_DEBUG=1 for the traceback)", EXIT_FAILED)


def _error(message: str, status: int) -> int:
    """Print one line: the message's first line, control characters escaped."""
    line = (message.splitlines() or [""])[0]
    print(f"chaingen: error: {line}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
