"""Ray casting of ellipsoids and rounded cones (``ghnerf_runtime.geometry.raycast``) at its degenerate and
large cases, and the body proxy (``ghnerf_runtime.body_proxy``) from degenerate joints: no NaN, no warning,
memory bounded. The simulated person's proxy and the culling are tested in ``test_proxy_blend`` and
``tests/drivers/sim/test_sim_truth.py``."""
from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.body_proxy import BodyProxy, proxy_body, proxy_depth
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
from ghnerf_runtime.geometry.raycast import RayGrid, rasterize


def prims(ells=(), cones=()) -> BodyProxy:
    E, C = len(ells), len(cones)

    def field(items, i, shape):
        return np.array([x[i] for x in items], float).reshape(shape)

    return BodyProxy(field(ells, 0, (E, 3)), field(ells, 1, (E, 3, 3)), field(ells, 2, (E, 3)),
                     field(cones, 0, (C, 3)), field(cones, 1, (C, 3)), field(cones, 2, (C,)), field(cones, 3, (C,)))


def camera(size: int = 64, fov: float = 60.0) -> Camera:
    """At the origin, looking down +z (the primitives above are in its frame)."""
    return Camera("c", size, size, intrinsics_from_fov(size, size, fov))


def cast(body, cam: Camera, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a divide by zero or NaN comparison is a defect here
        return rasterize(body, RayGrid.for_camera(cam), **kw)


def sphere_depth(cam: Camera, centre, r) -> np.ndarray:
    """The exact depth of a sphere per pixel (inf off it)."""
    xy = cam.pixels_to_normalized(cam.pixel_grid())
    d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
    c = np.asarray(centre, float)
    dd, cd = (d * d).sum(-1), d @ c
    disc = cd * cd - dd * (c @ c - r * r)
    return np.where(disc >= 0, (cd - np.sqrt(np.maximum(disc, 0))) / dd, np.inf)


@pytest.mark.parametrize("rb", [0.05, 0.03, 0.08])
def test_a_zero_length_cone_is_its_larger_sphere(rb):
    """A limb of zero length (elbow on wrist: the proxy's hand; heel on toes: its foot) divided by its length:
    NaN axes and RuntimeWarnings. Its hull is its larger sphere."""
    cam = camera()
    centre = [0.03, -0.02, 0.5]
    got = cast(prims(cones=[(centre, centre, 0.05, rb)]), cam)
    want = sphere_depth(cam, centre, max(0.05, rb))
    np.testing.assert_array_equal(np.isfinite(got.depth), np.isfinite(want))
    assert np.isfinite(want).sum() > 20
    np.testing.assert_allclose(got.depth[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-9)


def test_a_cone_whose_sphere_holds_the_other_is_that_sphere():
    cam = camera()
    got = cast(prims(cones=[([0.0, 0.0, 2.0], [0.0, 0.01, 2.0], 0.2, 0.05)]), cam)
    want = sphere_depth(cam, [0.0, 0.0, 2.0], 0.2)
    np.testing.assert_array_equal(np.isfinite(got.depth), np.isfinite(want))


@pytest.mark.parametrize("axes,radii", [
    (np.eye(3), [0.2, 0.0, 0.1]),  # a head from two ears at one point: radius 0
    (np.diag([1.0, 0.0, 0.0]), [0.1, 0.2, 0.3]),  # a torso whose neck is on its mid-hip: an axis lost
    (np.eye(3), [0.2, np.nan, 0.1]),
])
def test_an_ellipsoid_that_is_not_solid_hits_nothing(axes, radii):
    """A zero radius divided by zero; a lost axis made an endless slab that hit the pixels of its window."""
    cam = camera()
    good = ([0.0, 0.0, 2.0], np.eye(3), [0.1, 0.1, 0.1])
    got = cast(prims(ells=[([0.4, 0.0, 2.0], axes, radii), good]), cam)
    want = sphere_depth(cam, [0.0, 0.0, 2.0], 0.1)
    np.testing.assert_array_equal(np.isfinite(got.depth), np.isfinite(want))
    assert set(np.unique(got.prim)) == {-1, 1}


def test_passes_of_any_size_cast_what_one_pass_casts():
    rng = np.random.default_rng(3)
    cam = camera(48, 90)
    ells = [(rng.normal(0, 0.3, 3) + [0, 0, 1.5], look_at(rng.normal(size=3), [0, 0, 0])[0], rng.uniform(0.05, 0.3, 3))
            for _ in range(4)]
    cones = [(rng.normal(0, 0.4, 3) + [0, 0, 1.2], rng.normal(0, 0.4, 3) + [0, 0, 1.2], *rng.uniform(0.02, 0.2, 2))
             for _ in range(8)]
    cones.append(([0, 0, 1.0], [0, 0, 1.0], 0.1, 0.1))  # ties with the sphere below: the higher id wins
    cones.append(([0, 0, 1.0], [0, 0, 1.0], 0.1, 0.1))
    body = prims(ells, cones)
    one = cast(body, cam)
    assert np.isfinite(one.depth).mean() > 0.3
    for chunk in (1, 97, 1000, 5000):
        part = cast(body, cam, chunk=chunk)
        for field in ("depth", "prim", "fg_pixel", "fg_prim", "fg_depth"):
            a, b = getattr(one, field), getattr(part, field)
            assert a.dtype == b.dtype and np.array_equal(a, b), (chunk, field)
    assert np.all(np.diff(one.fg_prim) >= 0)  # grouped by primitive (the simulator's shading slices them)


def test_a_camera_inside_the_body_casts_in_bounded_memory():
    """Primitives crossing the camera plane have the whole image as their window: 40 of them at 224x224 were
    2 M (primitive, pixel) pairs intersected at once, 600 MB and more (14 pairs per pixel inside the body
    proxy: 56 M, some 17 GB, at 2000x2000)."""
    cam = camera(224, 100)
    rng = np.random.default_rng(0)
    around = rng.normal(0, 1.0, (40, 3)) * [1, 1, 0.05]  # about the camera plane
    body = prims(cones=[(p, p + rng.normal(0, 0.3, 3), 0.1, 0.08) for p in around])
    tracemalloc.start()
    try:
        got = cast(body, cam)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert np.isfinite(got.depth).mean() > 0.2  # it casts something
    assert peak < 150 * 2**20, f"{peak / 2**20:.0f} MB"


def _person() -> np.ndarray:
    """A standing person's BODY_25 joints 3 m in front of :func:`camera` (camera frame: y down)."""
    j = np.zeros((25, 3))
    at = {"Nose": (0, -0.62, -0.1), "Neck": (0, -0.45, 0), "RShoulder": (-0.2, -0.45, 0), "RElbow": (-0.25, -0.15, 0),
          "RWrist": (-0.27, 0.1, 0), "LShoulder": (0.2, -0.45, 0), "LElbow": (0.25, -0.15, 0), "LWrist": (0.27, 0.1, 0),
          "MidHip": (0, 0.1, 0), "RHip": (-0.1, 0.1, 0), "RKnee": (-0.11, 0.55, 0), "RAnkle": (-0.12, 0.95, 0),
          "LHip": (0.1, 0.1, 0), "LKnee": (0.11, 0.55, 0), "LAnkle": (0.12, 0.95, 0), "REye": (-0.03, -0.65, -0.08),
          "LEye": (0.03, -0.65, -0.08), "REar": (-0.07, -0.63, 0), "LEar": (0.07, -0.63, 0),
          "LBigToe": (0.12, 1.0, -0.15), "LSmallToe": (0.16, 1.0, -0.12), "LHeel": (0.12, 1.0, 0.05),
          "RBigToe": (-0.12, 1.0, -0.15), "RSmallToe": (-0.16, 1.0, -0.12), "RHeel": (-0.12, 1.0, 0.05)}
    for name, p in at.items():
        j[JOINT_INDEX[name]] = p
    return j + [0, 0, 3.0]


@pytest.mark.parametrize("case", ["all at one point", "zero-length forearm", "zero-length foot", "ears at one point",
                                  "ears centred on the neck", "neck on the mid-hip"])
def test_the_proxy_of_degenerate_joints_is_finite_and_warns_of_nothing(case):
    cam = camera(96, 60)
    j = _person()
    normal = proxy_depth(proxy_body(j, np.ones(25, bool)), cam)
    J = JOINT_INDEX
    if case == "all at one point":
        j[:] = j[J["MidHip"]]
    elif case == "zero-length forearm":
        j[J["RWrist"]] = j[J["RElbow"]]
    elif case == "zero-length foot":
        j[[J["LHeel"], J["LBigToe"], J["LSmallToe"]]] = j[J["LHeel"]]
    elif case == "ears at one point":
        j[J["LEar"]] = j[J["REar"]]
    elif case == "ears centred on the neck":
        j[J["Neck"]] = 0.5 * (j[J["REar"]] + j[J["LEar"]])
    else:
        j[J["Neck"]] = j[J["MidHip"]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        depth = proxy_depth(proxy_body(j, np.ones(25, bool)), cam)
    assert np.isfinite(depth).all() and (depth >= 0).all()
    assert 0 < (depth > 0).sum() <= 1.5 * (normal > 0).sum()  # what is left is drawn; nothing endless


def test_a_bad_girth_scale_or_joint_array_is_named():
    # a NaN scale gave NaN primitives, each cast over the whole view to hit nothing; 24 joints an IndexError
    from ghnerf_runtime.errors import GeometryError, ShapeError

    j = _person()
    for bad in (float("nan"), 0.0, -1.0, float("inf")):
        with pytest.raises(GeometryError, match=r"proxy_body: scale \(the girth factor\) must be a positive finite"):
            proxy_body(j, np.ones(25, bool), scale=bad)
    with pytest.raises(ShapeError, match=r"joints must be \(25, 3\) with \(25,\) valid flags, got \(24, 3\)"):
        proxy_body(j[:24], np.ones(24, bool))
    with pytest.raises(ShapeError, match=r"got \(25, 3\) and \(24,\)"):
        proxy_body(j, np.ones(24, bool))
    assert not proxy_body(j, np.ones(25, bool), scale=1.2).empty
