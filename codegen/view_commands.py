"""The commands that draw: `chaingen plot` (trajectory files, a sweep's metric) and `chaingen
animate` (a planar or spatial scene's run, views.animate), beside the others in chaingen.cli."""
from __future__ import annotations

import sys

import numpy as np

from .arguments import load_command_scene, newton_overrides
from .errors import ChaingenError, NewtonError, RunFailedError
from .runtime.files import check_output_file


def command_plot(args) -> int:
    if len(args.trajectories) == 1 and args.trajectories[0].is_dir():
        from .views.sweep_plot import plot_sweep

        if args.metric is None:
            raise ChaingenError(f"--metric: {args.trajectories[0]} is a sweep directory: name "
                                "the metric to draw")
        print(f"wrote {plot_sweep(args.trajectories[0], args.metric, args.output)}")
        return 0
    # --metric draws a sweep's column; trajectory files have none to draw: refused, not
    # ignored. A sweep directory among trajectory files is named as what it is.
    for path in args.trajectories:
        if path.is_dir():
            raise ChaingenError(f"{path}: a directory: a sweep's results are drawn alone "
                                "(chaingen plot OUT --metric METRIC), not among trajectory "
                                "files")
    if args.metric is not None:
        raise ChaingenError(f"--metric: only for a sweep's result directory; "
                            f"{args.trajectories[0]} is a trajectory file")
    from .views.plots import plot_files

    print(f"wrote {plot_files(args.trajectories, args.output)}")
    return 0


def command_animate(args) -> int:
    from .simulation import run_settings, simulate_scene
    from .views.animate import animate, check_fps
    from .views.plots import load_run, run_from_result

    scene = load_command_scene(args.scene)
    check_fps(args.fps)
    from .runtime.trajectory import metadata_path
    check_output_file(args.output, "-o", [args.scene] + (
        [args.trajectory, metadata_path(args.trajectory)] if args.trajectory else []))
    if args.t_end is not None and not (np.isfinite(args.t_end) and args.t_end > 0):
        raise ChaingenError(f"--t-end: must be > 0 and finite, got {args.t_end}")
    if args.trajectory is not None:
        # Every option of the run (the scheme, dt, the Newton options): none would change a
        # run already made, so one given is refused rather than ignored.
        given = [name for name in ("method", "quadrature", "gradient", "order", "dt")
                 if getattr(args, name) is not None] + list(newton_overrides(args))
        if given:
            flags = "/".join("--" + name.replace("_", "-") for name in given)
            raise ChaingenError(f"{flags}: only when animate simulates; the trajectory "
                                f"{args.trajectory} is already a run")
        run = load_run(args.trajectory)
    else:
        from .views.animate import check_output
        check_output(args.output)
        settings = run_settings(scene, method=args.method,
                                quadrature=args.quadrature, dt=args.dt, t_end=args.t_end,
                                order=args.order, gradient=args.gradient,
                                rtol=args.rtol, atol=args.atol, source=str(args.scene))
        try:
            result = simulate_scene(scene, settings, options=newton_overrides(args))
        except NewtonError as error:
            print(f"chaingen: error: simulation of {args.scene} failed: {error}",
                  file=sys.stderr)
            return RunFailedError.exit_status   # a run that failed: 1
        run = run_from_result(result, args.scene)
    if args.t_end is not None:
        run = run.until(args.t_end)
    out, plan = animate(scene, run, args.output, fps=args.fps, every=args.every,
                        pixels=args.size)
    print(f"wrote {out}: {plan.indices.size} frames at {plan.fps:g} fps, every "
          f"{plan.every} samples ({plan.playback_speed:g} x real time)")
    return 0
