"""The README's figures: `python -m chaingen.views.readme_figures [--out docs/figures]`.

For each reference scene, the standard run (the scene's dt and t_end) with every scheme,
overlaid in one figure of `chaingen plot` (joint angles, energy error, constraint error), as the
thesis's Figs. 5.3 and 5.5 compare schemes; and an animation of three_link_multi's es run, whose
multi-articular spring runs through all four fastenings. The runs go through the same code as
`chaingen simulate --out`, `plot` and `animate`.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from ..errors import ChaingenError
from ..runtime import write_trajectory
from ..scene import METHODS, STANDARD_SCENES, load_reference_scene
from ..simulation import run_settings, simulate_scene
from .animate import animate
from .plots import load_run, plot_files

#: The animation: scene, seconds shown, frame size in pixels.
ANIMATION = ("three_link_multi", 20.0, 400)


def write_figures(out: Path, *, t_end: float | None = None) -> list[Path]:
    """The figures into `out`; t_end shortens every run (default: each scene's own)."""
    written = []
    with tempfile.TemporaryDirectory(prefix="chaingen-figures-") as scratch:
        for name in STANDARD_SCENES:
            scene = load_reference_scene(name)
            paths = []
            for method in METHODS:
                result = simulate_scene(scene, run_settings(scene, method=method, t_end=t_end))
                paths.append(write_trajectory(result, Path(scratch) / f"{method}.csv"))
            figure = plot_files(paths, out / f"{name}.png")
            written.append(figure)
            print(f"wrote {figure}", flush=True)
            if name == ANIMATION[0]:
                scene_shown, seconds, pixels = ANIMATION
                run = load_run(paths[0]).until(min(seconds, t_end or seconds))
                gif, plan = animate(scene, run, out / f"{scene_shown}.gif", pixels=pixels)
                written.append(gif)
                print(f"wrote {gif}: {plan.indices.size} frames at {plan.fps:g} fps", flush=True)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m chaingen.views.readme_figures",
                                     description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs") / "figures",
                        help="directory of the figures (default: docs/figures, from the "
                             "checkout's root)")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        write_figures(args.out)
    except ChaingenError as error:
        print(f"figures: error: {error}", file=sys.stderr)
        return 2
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
