"""Ground truth of the simulated scene is self-consistent and agrees with an independent ray check."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.sim import PART_ID, PART_NAMES, RigPlacement, SceneConfig, SensorModel, SimScene
from drivers.sim.body import PosedBody
from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at

CASES = [("wave", 0.3, 0.0), ("walk", 1.7, 0.0), ("squat", 1.1, 35.0), ("reach", 0.9, 180.0), ("turn", 2.2, 0.0)]


@pytest.fixture(scope="module")
def rig():
    return RigPlacement().build()


@pytest.fixture(scope="module")
def distorted_rig():
    return RigPlacement(distortion=(-0.12, 0.03, 0.001, -0.0005, 0.0)).build()


def _scene(motion: str, heading: float = 0.0, seed: int = 5) -> SimScene:
    return SimScene(SceneConfig(seed=seed, motion=motion, heading_deg=heading))


@pytest.mark.parametrize("motion,t,heading", CASES)
def test_truth_consistency(rig, distorted_rig, motion, t, heading):
    scene = _scene(motion, heading)
    joints = scene.joints_3d(t)
    for cam in rig.cameras + distorted_rig.cameras:
        image, truth = scene.render(cam, t)
        assert image.shape == (cam.height, cam.width, 3) and image.dtype == np.uint8
        uv, z = cam.project(joints)
        assert np.all(z > 0)
        np.testing.assert_allclose(truth.joints_2d, uv, atol=1e-9)
        # mask == finite depth == labelled pixels; only background depth is non-finite (inf).
        assert truth.mask.dtype == bool and truth.depth.dtype == np.float32 and truth.part_labels.dtype == np.uint8
        np.testing.assert_array_equal(truth.mask, np.isfinite(truth.depth))
        np.testing.assert_array_equal(truth.mask, truth.part_labels > 0)
        assert not np.any(np.isnan(truth.depth)) and np.all(np.isposinf(truth.depth[~truth.mask]))
        assert truth.part_labels.max() <= len(PART_NAMES) and truth.mask.sum() > 2000
        assert np.all(np.isfinite(truth.joints_2d))
        # Near a visible joint's pixel (3x3, for joints on a silhouette) the nearest surface is at
        # the joint's depth, give or take how deep the joint sits under the skin.
        r = np.rint(uv[:, 1]).astype(int).clip(1, cam.height - 2)
        c = np.rint(uv[:, 0]).astype(int).clip(1, cam.width - 2)
        near = np.min([truth.depth[r + dy, c + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
        radius = scene.body.joint_radius
        vis = truth.visible
        assert vis.sum() >= 10
        on_body = vis & np.isfinite(near)
        assert on_body.sum() >= 10
        assert np.all(near[on_body] <= z[on_body] + 0.03), "surface well behind a visible joint"
        centre = truth.depth[r, c]
        assert np.all(centre[vis] >= z[vis] - radius[vis] - 0.03), "visible joint buried"
        # Hidden in-image joints are behind some surface, or on skin that faces away.
        posed = scene.posed(t)
        facing = np.einsum("ka,ka->k", posed.joint_normals, cam.center - posed.joints) >= 0
        hidden = ~vis & (uv[:, 0] > 1) & (uv[:, 0] < cam.width - 2) & (uv[:, 1] > 1) & (uv[:, 1] < cam.height - 2)
        assert np.all(centre[hidden & facing] < z[hidden & facing] - radius[hidden & facing] - 0.02)
        assert np.all(facing[vis])


def test_face_and_foot_visibility_follow_the_heading(rig):
    cam = rig.cameras[0]
    names = ("Nose", "REye", "LEye", "RBigToe", "LBigToe")
    _, front = _scene("stand", 0.0).render(cam, 0.0)
    _, back = _scene("stand", 180.0).render(cam, 0.0)
    for name in names:
        assert front.visible[JOINT_INDEX[name]], f"{name} hidden from the front"
        assert not back.visible[JOINT_INDEX[name]], f"{name} visible from behind"
    for name in ("RHeel", "LHeel"):
        assert back.visible[JOINT_INDEX[name]] and not front.visible[JOINT_INDEX[name]]


def test_face_and_foot_joints_sit_on_the_surface():
    scene = _scene("stand", 0.0)
    posed = scene.posed(0.0)
    j = posed.joints
    head = scene.look.head_prim
    # Distance of each surface landmark to the nearest primitive surface (implicit value ~ 1).
    for name in ("Nose", "REye", "LEye", "REar", "LEar", "RBigToe", "LBigToe", "RSmallToe", "LSmallToe", "RHeel", "LHeel"):
        assert _distance_to_surface(posed, j[JOINT_INDEX[name]]) < 2e-3, name
    # Facing the rig (heading 0) means facing -z: nose and eyes in front of the head centre,
    # ears beside it; person's right (R*) on the rig's -x side; toes ahead of heels.
    c = posed.ell_center[head]
    assert j[JOINT_INDEX["Nose"], 2] < c[2] - 0.08
    assert j[JOINT_INDEX["REye"], 2] < c[2] - 0.05 and j[JOINT_INDEX["REye"], 1] < j[JOINT_INDEX["Nose"], 1]
    assert j[JOINT_INDEX["REar"], 0] < c[0] - 0.06 < c[0] + 0.06 < j[JOINT_INDEX["LEar"], 0]
    assert j[JOINT_INDEX["RShoulder"], 0] < 0 < j[JOINT_INDEX["LShoulder"], 0]
    for side in "RL":
        assert j[JOINT_INDEX[f"{side}BigToe"], 2] < j[JOINT_INDEX[f"{side}Ankle"], 2] - 0.08 < j[JOINT_INDEX[f"{side}Heel"], 2] - 0.08
        assert abs(j[JOINT_INDEX[f"{side}Heel"], 1]) < 0.03  # on the floor (y = 0)
    assert abs(-j[:, 1].min() - scene.skeleton.params.height_m) < 0.15  # the eyes are below the crown


def test_depth_matches_independent_ray_march(rig, distorted_rig):
    scene = _scene("walk", 0.0)
    t = 0.8
    posed = scene.posed(t)
    rng = np.random.default_rng(0)
    for cam in (rig.cameras[1], distorted_rig.cameras[0]):
        _, truth = scene.render(cam, t)
        labels = truth.part_labels.astype(int)
        # Avoid silhouettes and part boundaries (grazing rays), where a fixed march step can skip.
        pad = np.pad(labels, 3, mode="edge")
        same = np.ones_like(truth.mask)
        for dy in range(-3, 4):
            for dx in range(-3, 4):
                same &= pad[3 + dy:3 + dy + cam.height, 3 + dx:3 + dx + cam.width] == labels
        fg = np.argwhere(truth.mask & same)
        bg = np.argwhere(~truth.mask & same)
        pick = np.concatenate([fg[rng.choice(len(fg), 50, replace=False)], bg[rng.choice(len(bg), 30, replace=False)]])
        uv = pick[:, ::-1].astype(float)
        origins, dirs = cam.rays(uv)
        t_hit = _march(posed, origins[0], dirs, near=1.0, far=6.0, step=0.001)
        # Camera z of the hit = distance along the ray times the ray's z component in the camera.
        z = t_hit * (dirs @ cam.R[2])
        expected = np.where(np.isfinite(t_hit), z, np.inf)
        got = truth.depth[pick[:, 0], pick[:, 1]].astype(np.float64)
        np.testing.assert_array_equal(np.isfinite(got), np.isfinite(expected))
        fin = np.isfinite(got)
        np.testing.assert_allclose(got[fin], expected[fin], atol=2e-4)


def test_joints_behind_or_outside_are_invisible():
    scene = _scene("stand")
    K = intrinsics_from_fov(160, 120, 60)
    R, t = look_at([0.0, -1.0, 0.0], [0.0, -1.0, -3.0])  # looking away from the person
    away = Camera("away", 160, 120, K, np.zeros(5), R, t)
    image, truth = scene.render(away, 0.0)
    assert not truth.mask.any() and not truth.visible.any()
    np.testing.assert_array_equal(truth.joints_2d, -1.0)  # behind the camera: documented (-1, -1)
    R, t = look_at([0.0, -1.0, 0.0], [3.0, -1.0, 3.0])  # person outside the field of view
    side = Camera("side", 160, 120, K, np.zeros(5), R, t)
    _, truth = scene.render(side, 0.0)
    assert not truth.visible.any() and np.all(np.isfinite(truth.joints_2d))


def test_part_labels_are_where_the_parts_are(rig):
    scene = SimScene(SceneConfig(seed=1, motion="stand", sensor=SensorModel(read_noise=0.0)))
    cam = rig.cameras[0]
    _, truth = scene.render(cam, 0.0)
    uv, _ = cam.project(scene.joints_3d(0.0))

    def label_at(name: str) -> str:
        u, v = np.rint(uv[JOINT_INDEX[name]]).astype(int)
        return PART_NAMES[truth.part_labels[v, u] - 1]

    assert label_at("Nose") == "head"
    assert label_at("MidHip") == "torso"
    # The hand ellipsoid hangs below the wrist joint.
    u, v = np.rint(uv[JOINT_INDEX["RWrist"]]).astype(int)
    assert PART_ID["r_hand"] in truth.part_labels[v:v + 15, u - 3:u + 4]
    assert set(np.unique(truth.part_labels)) >= {0, PART_ID["torso"], PART_ID["l_shin"], PART_ID["r_foot"]}


# ----------------------------------------------------------------- the reference
def _inside(posed: PosedBody, p: np.ndarray) -> np.ndarray:
    """Point-in-body test ``(...,)`` written independently of the renderer's quadratics."""
    inside = np.zeros(p.shape[:-1], dtype=bool)
    for c, axes, r in zip(posed.ell_center, posed.ell_axes, posed.ell_radii):
        inside |= np.sum((((p - c) @ axes) / r) ** 2, axis=-1) <= 1.0
    for a, b, ra, rb in zip(posed.cone_a, posed.cone_b, posed.cone_ra, posed.cone_rb):
        inside |= np.sum((p - a) ** 2, axis=-1) <= ra**2
        inside |= np.sum((p - b) ** 2, axis=-1) <= rb**2
        L = np.linalg.norm(b - a)
        w = (b - a) / L
        s = (ra - rb) / L
        h = (p - a) @ w
        q = np.linalg.norm((p - a) - h[..., None] * w, axis=-1)
        inside |= (h >= ra * s) & (h <= L + rb * s) & (q * np.sqrt(1 - s * s) + h * s <= ra)
    return inside


def _march(posed: PosedBody, origin: np.ndarray, dirs: np.ndarray, near: float, far: float, step: float) -> np.ndarray:
    ts = np.arange(near, far, step)
    hit = np.full(len(dirs), np.inf)
    for i, d in enumerate(dirs):
        flags = _inside(posed, origin + ts[:, None] * d)
        if not flags.any():
            continue
        k = int(np.argmax(flags))
        lo, hi = ts[k - 1], ts[k]
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if _inside(posed, origin + mid * d):
                hi = mid
            else:
                lo = mid
        hit[i] = hi
    return hit


def _distance_to_surface(posed: PosedBody, x: np.ndarray) -> float:
    """Distance from ``x`` to the body surface, by probing spheres of growing radius."""
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(4000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    inside_here = bool(_inside(posed, x))
    for r in np.linspace(1e-4, 0.01, 100):
        if np.any(_inside(posed, x + r * dirs) != inside_here):
            return float(r)
    return np.inf


@pytest.mark.parametrize("dist,eye", [
    ((), (0.0, -1.3, 0.0)),
    ((-0.3, 0.09, 0.002, -0.001, -0.01), (0.4, -1.0, 1.6)),  # strong barrel, close: parts leave the view
    ((), (0.1, -1.0, 2.75)),  # inside the arms' reach: primitives cross the near plane
])
def test_culling_drops_no_pixel(dist, eye, monkeypatch):
    from drivers.sim.raycast import RayGrid, rasterize

    scene = _scene("arm_circles")
    R, t = look_at(eye, [0.0, -1.1, 3.0])
    cam = Camera("c", 200, 150, intrinsics_from_fov(200, 150, 70), np.asarray(dist or np.zeros(5)), R, t)
    local = scene.posed(0.4).transformed(cam.R, cam.t)
    grid = RayGrid.for_camera(cam)
    culled = rasterize(local, grid)
    n = len(local.ell_center) + len(local.cone_a)
    monkeypatch.setattr(RayGrid, "windows", lambda self, body: np.tile([0, cam.height, 0, cam.width], (n, 1)))
    full = rasterize(local, grid)
    np.testing.assert_array_equal(culled.depth, full.depth)
    np.testing.assert_array_equal(culled.prim, full.prim)
    assert full.fg_pixel.size > 0


def test_a_joint_past_the_lens_fold_is_not_visible_at_its_mirrored_pixel():
    """k1 = -0.5, k2 = 0.05 folds at r = 0.874, inside the 160x120 image. The mid-hip at normalised
    (0.85, 0.72) (r = 1.11) is past it, yet inside the angle box of the image's pixels: the truth put it at
    the mirrored pixel (128.0, 100.6) and called it visible, though no pixel of the frame shows it."""
    import cv2

    scene = _scene("stand")
    j = JOINT_INDEX["MidHip"]
    eye = np.array([0.0, -1.0, 0.5])
    R0, _ = look_at(eye, scene.posed(0.0).joints[j])  # the joint on the optical axis ...
    a = np.array([0.85, 0.72, 1.0]) / np.linalg.norm([0.85, 0.72, 1.0])
    axis = np.cross([0.0, 0.0, 1.0], a)
    R = cv2.Rodrigues(axis / np.linalg.norm(axis) * np.arcsin(np.linalg.norm(axis)))[0] @ R0  # ... turned out
    cam = Camera("fold", 160, 120, [[125.0, 0.0, 79.5], [0.0, 125.0, 59.5], [0.0, 0.0, 1.0]],
                 [-0.5, 0.05, 0.0, 0.0, 0.0], R, -R @ eye)
    pc = cam.to_camera(scene.posed(0.0).joints[j])
    assert cam.fold_radius < np.hypot(*(pc[:2] / pc[2])) and np.isnan(cam.project(scene.posed(0.0).joints[j])[0]).all()
    mirrored = cam.normalized_to_pixels(pc[:2] / pc[2])
    assert np.all((mirrored >= 0) & (mirrored < [160, 120]))  # where the lens model puts it
    _, truth = scene.render(cam, 0.0)
    assert not truth.visible[j]
    np.testing.assert_array_equal(truth.joints_2d[j], -1.0)
