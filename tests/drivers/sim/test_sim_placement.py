"""The rig placement builds the documented default rig, and a person in its volume is seen by both cameras."""
from __future__ import annotations

import numpy as np

from drivers.sim import BodyParams, RigPlacement, SceneConfig, SimScene


def test_default_rig_matches_its_documentation():
    rig = RigPlacement().build()
    left, right = rig.pair
    assert rig.names == ("left", "right") and (left.width, left.height) == (640, 480)
    assert abs(rig.baseline - 1.2) < 1e-12
    np.testing.assert_allclose(left.center, [-0.6, -1.3, 0.0], atol=1e-12)
    np.testing.assert_allclose(right.center, [0.6, -1.3, 0.0], atol=1e-12)
    # Both look at the target: it projects to the image centre.
    for cam in rig.pair:
        uv, _ = cam.project(RigPlacement().target)
        np.testing.assert_allclose(uv, [319.5, 239.5], atol=1e-9)
    angle = np.degrees(np.arccos(left.R[2] @ right.R[2]))
    assert 20 < angle < 25
    np.testing.assert_allclose(rig.volume.min_corner, [-0.8, -2.1, 2.0])
    np.testing.assert_allclose(rig.volume.max_corner, [0.8, 0.05, 4.0])


def test_a_tall_person_fits_anywhere_in_the_volume():
    rig = RigPlacement().build()
    lo, hi = rig.volume.min_corner, rig.volume.max_corner
    for x in (lo[0], hi[0]):
        for z in (lo[2], hi[2]):
            scene = SimScene(SceneConfig(seed=1, motion="stand", body=BodyParams(height_m=2.0), position_xz=(x, z)))
            box_lo, box_hi = scene.bounding_box(0.0)
            box_lo[[0, 2]] = np.maximum(box_lo[[0, 2]], [x - 0.25, z - 0.25])  # the standing body, not the arms' reach
            box_hi[[0, 2]] = np.minimum(box_hi[[0, 2]], [x + 0.25, z + 0.25])
            corners = np.array([[a, b, c] for a in (box_lo[0], box_hi[0]) for b in (box_lo[1], box_hi[1]) for c in (box_lo[2], box_hi[2])])
            for cam in rig.pair:
                uv, depth = cam.project(corners)
                assert np.all(depth > 0)
                assert np.all((uv >= 0) & (uv <= [cam.width - 1, cam.height - 1])), (cam.name, x, z)


def test_options_reach_the_cameras():
    rig = RigPlacement(width=320, height=200, hfov_deg=60, distortion=(-0.1, 0.01, 0.0, 0.0, 0.0), baseline_m=0.3,
                       convergence_deg=0.0, names=("a", "b")).build("r1")
    a, b = rig.pair
    assert rig.rig_id == "r1" and (a.width, a.height) == (320, 200) and a.has_distortion
    np.testing.assert_allclose(a.R[2], b.R[2])  # parallel optical axes
    assert abs(rig.baseline - 0.3) < 1e-12
    random = RigPlacement.random(np.random.default_rng(3))
    assert random.build().volume.contains(np.array([0.0, -1.0, random.distance_m]))
