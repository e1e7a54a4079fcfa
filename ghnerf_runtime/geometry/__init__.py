"""Pure rig geometry: cameras, projection, rays, triangulation. Arrays in, arrays out, no I/O."""
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at, nearest_rotation
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.geometry.triangulation import (
    TriangulationResult,
    TwoViewCameras,
    TwoViewSolution,
    check_two_views,
    solve_two_views,
    triangulate_dlt,
    triangulate_midpoint,
    triangulate_robust,
    triangulate_two_views,
)

__all__ = [
    "Camera", "Rig", "TriangulationResult", "TwoViewCameras", "TwoViewSolution", "WorkingVolume",
    "check_two_views", "intrinsics_from_fov", "look_at", "nearest_rotation", "solve_two_views",
    "triangulate_dlt", "triangulate_midpoint", "triangulate_robust", "triangulate_two_views",
]
