"""`chaingen animate` of a spatial scene: the arm and its springs in two orthographic views.

Every frame draws, from the trajectory's joint angles and the scene (docs/scene-format.md,
"Spatial scenes"), in the world frame: the base (its origin to joint 1), the links as segments
from joint origin to joint origin (the last link from its joint to its centre of mass), the
joints, the centres of mass, and every spring as a polyline through its route points, coloured
by its stretch (s - S_0) / S_0 as in the planar animation. Two orthographic views side by side,
the front (x-z, looking along +y) and the top (x-y, looking down -z), show what one view would
hide behind a link. The positions come from chaingen.spatial.dynamics (link_poses,
com_positions, route_positions), the numpy reference the schemes are checked against.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spatial.dynamics import com_positions, link_poses, route_positions
from ..spatial.values import SpatialScene
from .figure import matplotlib_figure

#: The two views: title and the world axes (0 x, 1 y, 2 z) on their horizontal and vertical.
VIEWS = (("front (x-z)", 0, 2), ("top (x-y)", 0, 1))
AXIS_NAMES = "xyz"


@dataclass(frozen=True, eq=False)
class SpatialFrameGeometry:
    """What one frame draws, in metres, world frame (rows are points (x, y, z))."""

    joints: np.ndarray               # (n, 3) origins of joints 1..n
    coms: np.ndarray                 # (n, 3) centres of mass of links 1..n
    links: np.ndarray                # (n + 1, 3) the links' polyline: joints 1..n, COM n
    springs: tuple[np.ndarray, ...]  # per spring (points, 3): its route points
    stretch: tuple[float, ...]       # per spring (s - S_0) / S_0 (S_0 = 0: s)


def spatial_frame_geometry(scene: SpatialScene, q) -> SpatialFrameGeometry:
    poses = link_poses(scene, q)
    joints = np.array([origin for _, origin in poses[1:]])
    coms = com_positions(scene, q)
    springs, stretch = [], []
    for spring, points in zip(scene.springs, route_positions(scene, q)):
        springs.append(points)
        length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        stretch.append((length - spring.rest_length) / spring.rest_length
                       if spring.rest_length > 0 else length)
    return SpatialFrameGeometry(joints=joints, coms=coms, links=np.vstack([joints, coms[-1:]]),
                                springs=tuple(springs), stretch=tuple(stretch))


def spatial_reach(scene: SpatialScene) -> float:
    """A radius about the world origin that holds the arm and its springs in every posture:
    link i's origin lies within c_i = sum_k<=i |xyz_k| of it (c_0 = 0 for the base), a point
    on link i within c_i plus the point's distance from that origin."""
    chain = np.concatenate([[0.0], np.cumsum([np.linalg.norm(link.joint.xyz)
                                              for link in scene.links])])
    reach = [chain[-1]]
    reach += [chain[i + 1] + np.linalg.norm(link.com) for i, link in enumerate(scene.links)]
    reach += [chain[point.link] + np.linalg.norm(point.point) for spring in scene.springs
              for point in spring.route]
    return max(float(max(reach)), 1e-3)


#: A spatial frame's margins in pixels: left of the first view, between the views, below and
#: above them, and on the right without and with the springs' colour bar.
MARGINS = {"left": 50.0, "between": 58.0, "bottom": 40.0, "top": 34.0, "right": 16.0,
           "right_with_bar": 104.0}


def spatial_frame_layout(pixels: int, springs: bool) -> tuple[int, int, float]:
    """Width and height in pixels of a frame `pixels` high (both even, as MP4's yuv420p needs)
    and the side of its two square views, side by side between the margins: each view as
    large as the planar frame's chain at the same --size."""
    right = MARGINS["right_with_bar" if springs else "right"]
    side = pixels - MARGINS["bottom"] - MARGINS["top"]
    width = round(MARGINS["left"] + 2.0 * side + MARGINS["between"] + right)
    return width + width % 2, pixels + pixels % 2, side


class SpatialDrawing:
    """Matplotlib artists of one frame of a spatial scene, updated in place by `draw`; the
    interface of views.animate.ChainDrawing (draw, rgb, drawn)."""

    def __init__(self, scene: SpatialScene, *, pixels: int, stretch_limit: float = 0.1,
                 title: str = ""):
        from matplotlib import colormaps
        from matplotlib.colors import Normalize

        self.scene = scene
        width, height, side = spatial_frame_layout(pixels, bool(scene.springs))
        self.figure = matplotlib_figure((width / 100.0, height / 100.0), 100,
                                        "chaingen animate")
        self.colormap = colormaps["coolwarm"]
        self.norm = Normalize(-stretch_limit, stretch_limit)
        radius = 1.08 * spatial_reach(scene)
        bottom = MARGINS["bottom"]
        self.views = []
        for index, (name, horizontal, vertical) in enumerate(VIEWS):
            left = MARGINS["left"] + index * (side + MARGINS["between"])
            axes = self.figure.add_axes((left / width, bottom / height, side / width,
                                         side / height))
            self.views.append(_View(axes, name, horizontal, vertical, radius, scene))
        self.clock = self.figure.text(8.0 / width, 1.0 - 6.0 / height, "", va="top",
                                      fontsize=7, family="monospace")
        if title:
            self.figure.suptitle(title, fontsize=7, x=0.6, y=1.0 - 4.0 / height, va="top")
        if scene.springs:
            from matplotlib.cm import ScalarMappable
            bar_axes = self.figure.add_axes((1.0 - 84.0 / width, bottom / height,
                                             12.0 / width, side / height))
            bar = self.figure.colorbar(ScalarMappable(norm=self.norm, cmap=self.colormap),
                                       cax=bar_axes)
            bar.set_label("stretch (s - S0) / S0", fontsize=6)
            bar.ax.tick_params(labelsize=6)
        self.canvas = self.figure.canvas

    def draw(self, q, t: float) -> SpatialFrameGeometry:
        geometry = spatial_frame_geometry(self.scene, q)
        for view in self.views:
            view.draw(geometry, self.colormap, self.norm)
        self.clock.set_text(f"t = {t:7.2f} s")
        return geometry

    def drawn(self) -> dict[str, dict]:
        """The points the artists hold now, by view name (what each view shows, its two world
        coordinates per point), for checks."""
        return {view.name: view.drawn() for view in self.views}

    def rgb(self) -> np.ndarray:
        """The rendered frame as an (height, width, 3) uint8 array."""
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()


class _View:
    """One orthographic view: the world's `horizontal` and `vertical` axes on the page."""

    def __init__(self, axes, name: str, horizontal: int, vertical: int, radius: float,
                 scene: SpatialScene):
        self.axes, self.name, self.horizontal, self.vertical = axes, name, horizontal, vertical
        axes.set_title(name, fontsize=8, pad=3)
        axes.set_xlabel(f"{AXIS_NAMES[horizontal]} [m]", fontsize=7, labelpad=2)
        axes.set_ylabel(f"{AXIS_NAMES[vertical]} [m]", fontsize=7, labelpad=2)
        axes.set_xlim(-radius, radius)
        axes.set_ylim(-radius, radius)
        axes.set_aspect("equal")
        axes.tick_params(labelsize=6)
        axes.grid(True, alpha=0.2)
        self.base, = axes.plot([], [], color="0.3", linewidth=3, solid_capstyle="butt",
                               zorder=1)
        self.links, = axes.plot([], [], color="0.35", linewidth=4, solid_capstyle="round",
                                zorder=2)
        self.springs = [axes.plot([], [], linewidth=2.0, zorder=4)[0] for _ in scene.springs]
        self.route_points = [axes.plot([], [], "s", color="0.2", markersize=3, zorder=6)[0]
                             for _ in scene.springs]
        self.joints, = axes.plot([], [], "o", color="white", markeredgecolor="black",
                                 markersize=6, zorder=5)
        self.coms, = axes.plot([], [], "o", color="black", markersize=3.5, zorder=6)

    def _set(self, line, points: np.ndarray) -> None:
        line.set_data(points[:, self.horizontal], points[:, self.vertical])

    def draw(self, geometry: SpatialFrameGeometry, colormap, norm) -> None:
        self._set(self.base, np.vstack([np.zeros(3), geometry.joints[0]]))
        self._set(self.links, geometry.links)
        for line, markers, points, stretch in zip(self.springs, self.route_points,
                                                  geometry.springs, geometry.stretch):
            self._set(line, points)
            line.set_color(colormap(norm(stretch)))
            self._set(markers, points)
        self._set(self.joints, geometry.joints)
        self._set(self.coms, geometry.coms)

    def drawn(self) -> dict[str, np.ndarray | list[np.ndarray]]:
        return {"links": self.links.get_xydata(), "joints": self.joints.get_xydata(),
                "coms": self.coms.get_xydata(),
                "springs": [line.get_xydata() for line in self.springs]}


def spatial_stretch_limit(scene: SpatialScene, qs: np.ndarray) -> float:
    """The colour scale: the largest |stretch| over the frames (at least 1e-3)."""
    largest = 1e-3
    for q in qs:
        stretch = spatial_frame_geometry(scene, q).stretch
        if stretch:
            largest = max(largest, max(abs(s) for s in stretch))
    return largest
