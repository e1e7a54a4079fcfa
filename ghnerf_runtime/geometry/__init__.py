"""Pure rig geometry: cameras, projection, rays, triangulation. Arrays in, arrays out, no I/O."""
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at, nearest_rotation
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.geometry.triangulation import (
    TriangulationResult,
    triangulate_dlt,
    triangulate_midpoint,
    triangulate_robust,
    triangulate_two_views,
)

__all__ = [
    "Camera", "Rig", "TriangulationResult", "WorkingVolume", "intrinsics_from_fov", "look_at",
    "nearest_rotation",
    "triangulate_dlt", "triangulate_midpoint", "triangulate_robust", "triangulate_two_views",
]
