"""The simulator's ray casting lives with the rest of the pure geometry
(``ghnerf_runtime.geometry.raycast``), which the runtime's body proxy shares; re-exported here."""
from ghnerf_runtime.geometry.raycast import (  # noqa: F401
    NEAR,
    Primitives,
    Raster,
    RayGrid,
    cone_coefficients,
    ellipsoid_coefficients,
    ellipsoid_depth,
    rasterize,
    round_cone_depth,
)
