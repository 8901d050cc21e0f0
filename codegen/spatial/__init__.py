"""Spatial scenes (issue 33, in progress): serial chains of revolute joints in 3D with URDF's
conventions, their numeric kinematics and dynamics (the reference of the spatial schemes), and
the import of robots from URDF files.

- values: the frozen SpatialScene, SpatialLink, SpatialJoint, SpatialSpring and RoutePoint;
- reader: reading and validating spatial scene files (docs/scene-format.md, "Spatial scenes");
- dynamics: numpy poses, mass matrix, generalized gravity and spring forces, energies.
"""
from .reader import load_spatial_scene, parse_spatial_scene
from .values import RoutePoint, SpatialJoint, SpatialLink, SpatialScene, SpatialSpring

__all__ = ["RoutePoint", "SpatialJoint", "SpatialLink", "SpatialScene", "SpatialSpring",
           "load_spatial_scene", "parse_spatial_scene"]
