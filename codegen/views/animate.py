"""`chaingen animate`: the chain drawn to scale with its springs, as GIF (Pillow) or MP4 (ffmpeg).

Every frame draws, from the trajectory's joint angles and the scene (model.md sections 1-2):
the links between the joints X_1..X_{n+1}, the joints, the COMs x_i, the fastenings P_j on
their stalks (normal offsets r_j from the joints), and every spring as a polyline through its
own fastenings P_first..P_{last+1}, coloured by its stretch (s - S_0) / S_0 (blue: shorter
than at rest, red: longer), with a time stamp. The positions come from `frame_geometry`, the
same numpy kinematics the tests check against the symbolic model.

The frame rate and decimation follow the trajectory's sample interval: by default 25 frames a
second in real time (every 4th sample at dt = 0.01 s), fewer when the samples are sparser;
`fps` and `every` override them.
"""
from __future__ import annotations

import math
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PlotError
from ..progress import Progress
from ..runtime.files import reported_write, staged_file
from ..runtime.trajectory import metadata_path
from ..scene import Scene
from ..scene.kinematics import chain_geometry, spring_geometry
from ..scene.parameters import with_values
from ..spatial.values import SpatialScene
from .animate_spatial import SpatialDrawing, spatial_stretch_limit
from .figure import matplotlib_figure
from .plots import TrajectoryRun

DEFAULT_FPS = 25.0
#: The slowest frame rate: a frame every 100 s (a GIF frame lasts at most 655.35 s, its
#: duration a 16-bit count of hundredths).
MIN_FPS = 0.01
#: GIF frame durations are whole hundredths of a second.
GIF_TICK_MS = 10
#: Frame size in pixels (square); even, as MP4's yuv420p needs.
DEFAULT_PIXELS = 480
MAX_FRAMES = 20000


@dataclass(frozen=True, eq=False)
class FrameGeometry:
    """What one frame draws, in metres (rows are points (x, y))."""

    joints: np.ndarray              # (n + 1, 2) X_1..X_{n+1}
    coms: np.ndarray                # (n, 2) x_1..x_n
    fastenings: np.ndarray          # (n + 1, 2) the chain's P_1..P_{n+1}
    springs: tuple[np.ndarray, ...]  # per spring (last - first + 2, 2): its P_first..P_{last+1}
    stretch: tuple[float, ...]      # per spring (sum_j s_j - S_0) / S_0 (S_0 = 0: sum_j s_j)


def frame_geometry(scene: Scene, phi) -> FrameGeometry:
    chain = chain_geometry(scene, phi)
    springs, stretch = [], []
    for spring in scene.springs:
        geometry = spring_geometry(scene, spring, phi)
        springs.append(np.array(geometry.points))
        length = geometry.total_length
        stretch.append((length - spring.rest_length) / spring.rest_length
                       if spring.rest_length > 0 else length)
    return FrameGeometry(joints=np.array(chain.joints), coms=np.array(chain.coms),
                         fastenings=np.array(chain.fastenings), springs=tuple(springs),
                         stretch=tuple(stretch))


def reach(scene: Scene) -> float:
    """A radius that holds the chain and its fastenings in every posture."""
    offsets = [abs(r) for r in scene.chain_fastenings()]
    for spring in scene.springs:
        offsets += [abs(r) for r in scene.spring_fastenings(spring)]
    return sum(link.length for link in scene.links) + max(offsets + [0.0])


@dataclass(frozen=True)
class FramePlan:
    """Which samples become frames, and how fast they play."""

    indices: np.ndarray   # sample rows drawn
    fps: float            # frames per second of the output
    every: int            # samples between frames
    sample_dt: float      # seconds between samples

    @property
    def playback_speed(self) -> float:
        """Simulated seconds per second of video (1: real time)."""
        return self.every * self.sample_dt * self.fps


def frame_plan(t: np.ndarray, *, fps: float | None = None, every: int | None = None,
               gif: bool = True) -> FramePlan:
    """Frames at `fps` in real time by default: every = round(1 / (fps * sample dt))."""
    if t.size < 1:
        raise PlotError("animate: the trajectory has no samples")
    sample_dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    if every is not None and every < 1:
        raise PlotError(f"--every: must be >= 1, got {every}")
    check_fps(fps)
    if every is None:
        every = max(1, round(1.0 / ((fps or DEFAULT_FPS) * sample_dt)))
    if fps is None:
        fps = max(MIN_FPS, min(DEFAULT_FPS * 2, 1.0 / (every * sample_dt)))
    if gif:   # a GIF frame lasts a whole number of hundredths
        fps = 1000.0 / (GIF_TICK_MS * max(2, round(1000.0 / (fps * GIF_TICK_MS))))
    # An every beyond the samples draws the first one alone; one past int64 (--every 10**20,
    # or --fps 0.01 on samples 1e-30 s apart) would not index them.
    indices = np.arange(0, t.size, min(every, t.size))
    if indices.size > MAX_FRAMES:
        raise PlotError(f"animate: {indices.size} frames (every {every} of {t.size} samples) is "
                        f"more than {MAX_FRAMES}; give a larger --every or a shorter --t-end")
    return FramePlan(indices=indices, fps=fps, every=every, sample_dt=sample_dt)


class ChainDrawing:
    """Matplotlib artists of one frame, updated in place by `draw`."""

    def __init__(self, scene: Scene, *, pixels: int = DEFAULT_PIXELS, stretch_limit: float = 0.1,
                 title: str = ""):
        self.scene = scene
        self.figure = matplotlib_figure((pixels / 100.0, pixels / 100.0), 100,
                                        "chaingen animate")
        from matplotlib import colormaps
        from matplotlib.colors import Normalize

        # Margins in pixels, so that the tick labels (with their minus signs) and the axis
        # labels stay inside the frame at any --size; the colour bar takes the right side.
        left, bottom, top = 58.0 / pixels, 44.0 / pixels, 1.0 - 30.0 / pixels
        right = 1.0 - (104.0 if scene.springs else 24.0) / pixels
        axes = self.figure.add_axes((left, bottom, right - left, top - bottom))
        self.axes = axes
        axes.set_xlabel("x [m]", fontsize=7, labelpad=2)
        axes.set_ylabel("y [m]", fontsize=7, labelpad=2)
        radius = 1.08 * reach(scene)
        axes.set_xlim(-radius, radius)
        axes.set_ylim(-radius, radius)
        axes.set_aspect("equal")
        axes.tick_params(labelsize=7)
        axes.grid(True, alpha=0.2)
        axes.plot([-0.12 * radius, 0.12 * radius], [0.0, 0.0], color="0.3", linewidth=3,
                  solid_capstyle="butt", zorder=1)   # the base
        self.colormap = colormaps["coolwarm"]
        self.norm = Normalize(-stretch_limit, stretch_limit)
        self.links, = axes.plot([], [], color="0.35", linewidth=5, solid_capstyle="round",
                                zorder=2)
        self.stalks = [axes.plot([], [], color="0.55", linewidth=1.2, zorder=2)[0]
                       for _ in range(scene.n + 1)]
        self.springs = [axes.plot([], [], linewidth=2.2, zorder=4)[0] for _ in scene.springs]
        self.joints, = axes.plot([], [], "o", color="white", markeredgecolor="black",
                                 markersize=7, zorder=5)
        self.coms, = axes.plot([], [], "o", color="black", markersize=4, zorder=6)
        self.fastenings, = axes.plot([], [], "s", color="0.2", markersize=4, zorder=6)
        self.spring_points = [axes.plot([], [], "s", color="0.2", markersize=3, zorder=6)[0]
                              for _ in scene.springs]
        self.clock = axes.text(0.03, 0.96, "", transform=axes.transAxes, va="top",
                               fontsize=9, family="monospace")
        if title:
            self.figure.suptitle(title, fontsize=9)
        if scene.springs:
            from matplotlib.cm import ScalarMappable
            bar_axes = self.figure.add_axes((1.0 - 84.0 / pixels, 0.12, 12.0 / pixels, 0.70))
            bar = self.figure.colorbar(ScalarMappable(norm=self.norm, cmap=self.colormap),
                                       cax=bar_axes)
            bar.set_label("spring stretch (s - S0) / S0", fontsize=7)
            bar.ax.tick_params(labelsize=6)
            self.bar = bar
        self.canvas = self.figure.canvas

    def draw(self, phi, t: float) -> FrameGeometry:
        geometry = frame_geometry(self.scene, phi)
        self.links.set_data(geometry.joints[:, 0], geometry.joints[:, 1])
        for stalk, joint, fastening in zip(self.stalks, geometry.joints, geometry.fastenings):
            stalk.set_data([joint[0], fastening[0]], [joint[1], fastening[1]])
        for line, markers, points, stretch in zip(self.springs, self.spring_points,
                                                  geometry.springs, geometry.stretch):
            line.set_data(points[:, 0], points[:, 1])
            line.set_color(self.colormap(self.norm(stretch)))
            markers.set_data(points[:, 0], points[:, 1])
        self.joints.set_data(geometry.joints[:, 0], geometry.joints[:, 1])
        self.coms.set_data(geometry.coms[:, 0], geometry.coms[:, 1])
        self.fastenings.set_data(geometry.fastenings[:, 0], geometry.fastenings[:, 1])
        self.clock.set_text(f"t = {t:7.2f} s")
        return geometry

    def drawn(self) -> dict[str, np.ndarray | list[np.ndarray]]:
        """The points the artists hold now (what the frame shows), for checks."""
        return {"links": self.links.get_xydata(), "joints": self.joints.get_xydata(),
                "coms": self.coms.get_xydata(), "fastenings": self.fastenings.get_xydata(),
                "springs": [line.get_xydata() for line in self.springs],
                "stalks": [line.get_xydata() for line in self.stalks]}

    def rgb(self) -> np.ndarray:
        """The rendered frame as an (height, width, 3) uint8 array."""
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()


def stretch_limit(scene: Scene, phis: np.ndarray) -> float:
    """The colour scale: the largest |stretch| over the frames (at least 1e-3)."""
    largest = 1e-3
    for phi in phis:
        stretch = frame_geometry(scene, phi).stretch
        if stretch:
            largest = max(largest, max(abs(s) for s in stretch))
    return largest


def check_fps(fps: float | None) -> None:
    if fps is not None and not (math.isfinite(fps) and MIN_FPS <= fps <= 100):
        raise PlotError(f"--fps: must be from {MIN_FPS:g} (a frame every "
                        f"{1 / MIN_FPS:g} s) to 100, got {fps:g}")


def check_matches(scene: Scene, run: TrajectoryRun) -> None:
    if run.n != scene.n:
        raise PlotError(f"{run.path}: {run.n} joints (phi1..phi{run.n}), but the scene "
                        f"{scene.name} has {scene.n} links")
    if run.scene is not None and run.scene != scene.name:
        raise PlotError(f"{run.path}: written for scene {run.scene!r} (its metadata file), "
                        f"not {scene.name!r}")


def run_scene(scene: Scene | SpatialScene, run: TrajectoryRun) -> Scene | SpatialScene:
    """The scene as the run had it: its run-time parameters' values (the metadata's) in place
    of the scene file's numbers; SceneError naming the file and path of one it cannot take.
    A spatial scene takes no run-time parameters (chaingen.scene.SolverSpec refuses them)."""
    if not run.parameters:
        return scene
    if isinstance(scene, SpatialScene):
        raise PlotError(f"{metadata_path(run.path)}: parameters: run-time parameters are "
                        f"planar-only so far; no run of the spatial scene {scene.name!r} has them")
    return with_values(scene, run.parameters, where=f"{metadata_path(run.path)}: parameters")


def check_output(out: Path) -> str | None:
    """Refuse an output the animation cannot write; returns ffmpeg's path for an .mp4."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise PlotError(f"-o: {out}: give a .gif or .mp4 file name")
    if not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise PlotError(f"-o: directory {out.parent} does not exist")
    if suffix == ".mp4":
        ffmpeg = shutil.which("ffmpeg")
        if ffmpeg is None:
            raise PlotError(f"-o: {out}: MP4 needs ffmpeg on the PATH, which is not there; "
                            "write a .gif instead (Pillow, no system dependency)")
        return ffmpeg
    return None


def animate(scene: Scene | SpatialScene, run: TrajectoryRun, out: Path, *,
            fps: float | None = None, every: int | None = None,
            pixels: int = DEFAULT_PIXELS) -> tuple[Path, FramePlan]:
    """Render `run` of `scene` to `out` (.gif, or .mp4 with ffmpeg); returns it and the plan.
    A planar scene's frames are `pixels` square; a spatial scene's (views.animate_spatial)
    are `pixels` high, its two views side by side."""
    out = Path(out)
    suffix = out.suffix.lower()
    ffmpeg = check_output(out)
    smallest = 200 if scene.springs else 100    # the springs' colour bar takes 104 pixels
    if pixels < smallest or pixels > 4000:
        raise PlotError(f"--size: must be between {smallest} and 4000 pixels"
                        f"{' for a scene with springs' if scene.springs else ''}, got {pixels}")
    pixels += pixels % 2
    check_matches(scene, run)
    scene = run_scene(scene, run)
    plan = frame_plan(run.t, fps=fps, every=every, gif=suffix == ".gif")
    phis = run.phi[plan.indices]
    title = f"{scene.name}: {run.label}"
    if isinstance(scene, SpatialScene):
        drawing = SpatialDrawing(scene, pixels=pixels,
                                 stretch_limit=spatial_stretch_limit(scene, phis), title=title)
    else:
        drawing = ChainDrawing(scene, pixels=pixels, stretch_limit=stretch_limit(scene, phis),
                               title=title)
    with reported_write(out, "the animation"), staged_file(out, suffix=suffix) as temporary, \
            Progress("animate", total=len(plan.indices), unit="frames") as progress:
        frames = _frames(drawing, run, plan, progress)
        if suffix == ".gif":
            _write_gif(frames, str(temporary), plan.fps)
        else:
            _write_mp4(frames, str(temporary), plan.fps, ffmpeg)
    return out, plan


def _frames(drawing: ChainDrawing | SpatialDrawing, run: TrajectoryRun, plan: FramePlan,
            progress: Progress):
    for count, index in enumerate(plan.indices, start=1):
        drawing.draw(run.phi[index], float(run.t[index]))
        yield drawing.rgb()
        progress(count)


def _write_gif(frames, path: str, fps: float) -> None:
    from PIL import Image

    images = [Image.fromarray(frame).quantize(colors=96, method=Image.Quantize.FASTOCTREE,
                                              dither=Image.Dither.NONE)
              for frame in frames]
    duration = GIF_TICK_MS * round(1000.0 / (fps * GIF_TICK_MS))
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:],
                   duration=duration, loop=0, disposal=1)


def _write_mp4(frames, path: str, fps: float, ffmpeg: str) -> None:
    process = None
    try:
        for frame in frames:
            if process is None:
                height, width, _ = frame.shape
                process = subprocess.Popen(
                    [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                     "-s", f"{width}x{height}", "-r", f"{fps:g}", "-i", "-", "-an",
                     "-pix_fmt", "yuv420p", "-f", "mp4", path],
                    stdin=subprocess.PIPE, stderr=subprocess.PIPE)
            process.stdin.write(frame.tobytes())
        if process is None:
            raise PlotError("animate: no frames to write")
        process.stdin.close()
        errors = process.stderr.read().decode(errors="replace").strip()
        if process.wait() != 0:
            reason = errors or f"exit {process.returncode}"
            raise PlotError(f"animate: ffmpeg failed: {reason}")
    finally:
        if process is not None:
            if process.poll() is None:
                process.kill()
                process.wait()
            for stream in (process.stdin, process.stderr):
                stream.close()
