"""Novel-view ray selection: the coarse silhouette pass renders only the cells the subject covers."""
from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.bench_runtime_common import edge128_contract
from ghnerf_runtime.config import ConfigError, NovelViewConfig
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
from ghnerf_runtime.novel_view import render_novel_view
from ghnerf_runtime.rays import cells_ray_uv, refine_cells, scatter_cells

BOX = np.array([[-0.4, -1.8, 2.6], [0.4, 0.0, 3.4]])
CENTRE = np.array([64.0, 64.0])
RADIUS = 14.0


class DiscSession:
    """Render graphs answer a coloured disc (model pixels) over the background; counts the rays.

    ``opaque_background``: every ray is opaque (acc 1), the background rays coloured as the background,
    as the shipped model renders its box.
    """

    def __init__(self, radius: float = RADIUS, opaque_background: bool = False):
        self.contract = edge128_contract()
        self.radius = radius
        self.opaque = opaque_background
        self.rays: list[int] = []

    def run(self, graph, feeds):
        if graph == "volume":
            return {"volume": np.zeros((1, 8, 4, 32, 32), np.float32),
                    "depth_stats": np.zeros((1, 4, 32, 32), np.float32)}
        uv = feeds["ray_uv"][0]
        self.rays.append(len(uv))
        inside = (np.linalg.norm(uv - CENTRE, axis=-1) <= self.radius).astype(np.float32)
        shade = 0.25 + 0.5 * (uv[:, 0] / 128.0)  # a gradient, so misplaced rays would show
        rgb = np.stack([shade * inside] * 3, axis=-1)
        acc = np.ones_like(inside) if self.opaque else inside
        out = {"rgb": rgb[None], "depth": (3.0 * acc)[None], "acc": acc[None]}
        if graph == "render":
            out["heatmaps"] = np.repeat(inside[None, :, None], 25, axis=-1)
        return out


def _camera() -> Camera:
    R, t = look_at((0.0, -0.9, 0.0), BOX.mean(axis=0))
    return Camera("novel", 128, 128, intrinsics_from_fov(128, 128, 40.0), np.zeros(5), R, t)


def _render(config: NovelViewConfig, session=None, want_heat: bool = False):
    session = session or DiscSession()
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    return render_novel_view(session, env, _camera(), BOX, config, want_heat=want_heat), session


DILATED = NovelViewConfig(enabled=True, silhouette_dilate=1)


def test_coarse_pass_renders_fewer_rays_and_the_same_subject():
    full, s_full = _render(NovelViewConfig(enabled=True, silhouette_stride=0))
    fast, s_fast = _render(DILATED)
    assert len(s_full.rays) == 1 and len(s_fast.rays) == 2  # coarse + fine
    assert fast.rays == sum(s_fast.rays) < full.rays / 2
    # Every pixel the subject covers is rendered exactly as before; the rest is background either way.
    np.testing.assert_array_equal(fast.image, full.image)
    np.testing.assert_array_equal(fast.depth, full.depth)


def test_default_coarse_pass_loses_at_most_the_rim():
    """Without dilation (the default) only pixels within one coarse cell of the edge can be dropped."""
    full, _ = _render(NovelViewConfig(enabled=True, silhouette_stride=0))
    fast, s_fast = _render(NovelViewConfig(enabled=True))
    assert fast.rays < _render(DILATED)[0].rays
    differ = np.any(fast.image != full.image, axis=-1)
    v, u = np.nonzero(differ)
    dist = np.hypot(u - CENTRE[0], v - CENTRE[1])
    assert differ.sum() < 0.25 * np.any(full.image > 0, axis=-1).sum()
    assert np.all(dist > RADIUS - 4 * np.sqrt(2))  # only near the edge, never inside
    assert not np.any(fast.image[~differ] != full.image[~differ])


def test_opaque_background_is_not_mistaken_for_the_subject():
    full, _ = _render(NovelViewConfig(enabled=True, silhouette_stride=0), DiscSession(opaque_background=True))
    fast, s = _render(DILATED, DiscSession(opaque_background=True))
    assert fast.rays < full.rays / 2
    np.testing.assert_array_equal(fast.image, full.image)


def test_thin_subject_between_coarse_rays_is_kept_by_dilation():
    # A disc of radius 1.5 px can fall between the 4-px coarse rays entirely: nothing found, all background,
    # never a stale or partial subject.
    tiny, _ = _render(DILATED, DiscSession(radius=1.5))
    tiny_full, _ = _render(NovelViewConfig(enabled=True, silhouette_stride=0), DiscSession(radius=1.5))
    assert tiny_full.image.any()
    assert not tiny.image.any() or np.array_equal(tiny.image, tiny_full.image)
    # A subject 4 px across is always hit by a coarse ray, and dilation brings in its whole extent.
    small_fast, _ = _render(DILATED, DiscSession(radius=4.0))
    small_full, _ = _render(NovelViewConfig(enabled=True, silhouette_stride=0), DiscSession(radius=4.0))
    np.testing.assert_array_equal(small_fast.image, small_full.image)


def test_empty_scene_renders_only_the_coarse_pass():
    nv, s = _render(NovelViewConfig(enabled=True), DiscSession(radius=0.0))
    assert len(s.rays) == 1 and nv.rays == s.rays[0]
    assert not nv.image.any() and not nv.depth.any()


def test_coarse_pass_with_heatmaps_and_stride():
    nv, s = _render(NovelViewConfig(enabled=True, stride=2, heatmaps=True), None, want_heat=True)
    assert len(s.rays) == 2 and nv.heat is not None and nv.heat.max() == 1.0
    off, s_off = _render(NovelViewConfig(enabled=True, stride=4, silhouette_stride=4))
    assert len(s_off.rays) == 1  # the coarse pass would be no coarser than the render: skipped


def test_silhouette_config_is_validated():
    assert NovelViewConfig(silhouette_stride=8, stride=2).coarse_pass
    assert not NovelViewConfig(silhouette_stride=0).coarse_pass
    with pytest.raises(ConfigError, match="silhouette_stride"):
        NovelViewConfig(stride=2, silhouette_stride=3)
    with pytest.raises(ConfigError, match="silhouette_min_diff"):
        NovelViewConfig(silhouette_min_diff=float("nan"))
    with pytest.raises(ConfigError, match="silhouette_dilate"):
        replace(NovelViewConfig(), silhouette_dilate=-1)


@pytest.mark.parametrize("value", [3, 5, 6, 10, 12, 14])
def test_a_silhouette_stride_that_does_not_tile_the_model_is_refused(value):
    """6 passed the old check (an int 0..16, a multiple of stride) and crashed the render at 128 (21 cells -> 126)."""
    with pytest.raises(ConfigError, match="silhouette_stride"):
        NovelViewConfig(silhouette_stride=value)
    for ok in (0, 1, 2, 4, 8, 16):
        assert NovelViewConfig(silhouette_stride=ok).silhouette_stride == ok


def _contract(size: int):
    from ghnerf_runtime.contract import ModelContract

    c = edge128_contract()
    return ModelContract.build(height=size, width=size, variant=c.variant, levels=c.levels, channels=c.channels,
                               strides=c.strides, encoder_heatmaps=True)


class OddSizeSession(DiscSession):
    """The disc session with a model of another square resolution."""

    def __init__(self, size: int):
        super().__init__()
        self.contract = _contract(size)


def test_strides_that_do_not_divide_the_model_resolution_are_a_config_error_not_a_crash():
    """A 120x120 model (the contract allows it): 16 does not divide 120; the render names the field."""
    env = {"images": np.zeros((2, 3, 120, 120), np.float32)}
    camera = _camera().resized(120, 120)
    with pytest.raises(ConfigError, match=r"novel_view\.silhouette_stride.*120"):
        render_novel_view(OddSizeSession(120), env, camera, BOX, NovelViewConfig(enabled=True, silhouette_stride=16))
    nv = render_novel_view(OddSizeSession(120), env, camera, BOX, NovelViewConfig(enabled=True, silhouette_stride=8))
    assert nv.image.shape == (120, 120, 3)


def test_the_estimator_checks_the_novel_strides_against_its_model_at_load():
    from benchmarks.bench_runtime_common import OracleSession
    from ghnerf_runtime.config import EstimatorConfig
    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.geometry.rig import Rig, WorkingVolume

    other = _camera()
    other = replace(other, name="other", t=other.t + [0.3, 0.0, 0.0])  # 30 cm to the side: a stereo pair
    rig = Rig((_camera().resized(640, 640), other.resized(640, 640)), WorkingVolume(BOX[0], BOX[1]))
    bad = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, silhouette_stride=16))
    with pytest.raises(ConfigError, match=r"novel_view\.silhouette_stride"):
        Estimator(OracleSession(_contract(120)), rig, bad)
    Estimator(OracleSession(_contract(128)), rig, bad).close()  # 16 divides 128
    Estimator(OracleSession(_contract(120)), rig, replace(bad, novel_view=NovelViewConfig())).close()  # no novel view


def test_cell_helpers_round_trip():
    mask = np.zeros((4, 5), bool)
    mask[1, 2] = mask[3, 0] = True
    uv = cells_ray_uv(mask, 4)
    np.testing.assert_array_equal(uv, [[9.5, 5.5], [1.5, 13.5]])
    grid = scatter_cells(np.array([[1.0], [2.0]]), mask, fill=-1.0)
    assert grid.shape == (4, 5, 1) and grid[1, 2, 0] == 1.0 and grid[3, 0, 0] == 2.0 and grid[0, 0, 0] == -1.0
    fine = refine_cells(mask, 2)
    assert fine.shape == (8, 10) and fine[2:4, 4:6].all() and fine.sum() == 8


class CheckerDiscSession(DiscSession):
    """A disc filled with a 1-px checkerboard: detail that sparse interior rays cannot reproduce."""

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph != "volume":
            uv = feeds["ray_uv"][0]
            checker = ((np.floor(uv[:, 0] + 0.5) + np.floor(uv[:, 1] + 0.5)) % 2).astype(np.float32)
            out["rgb"] = out["rgb"] * (0.5 + 0.5 * checker[None, :, None])
        return out


def test_sparse_interior_keeps_the_edges_and_fills_a_smooth_inside_exactly():
    big = 30.0
    full, s_full = _render(NovelViewConfig(enabled=True), DiscSession(radius=big))
    fast, s_fast = _render(NovelViewConfig(enabled=True, interior_stride=2), DiscSession(radius=big))
    assert len(s_fast.rays) == 2  # the coarse pass, then edge and interior rays in one run
    assert s_fast.rays[1] < 0.7 * s_full.rays[1] and fast.rays == sum(s_fast.rays)
    # The disc's shade is linear in u: bilinear filling of the interior reproduces it.
    assert np.abs(fast.image.astype(int) - full.image.astype(int)).max() <= 1
    np.testing.assert_allclose(fast.depth, full.depth, atol=1e-5)


def test_sparse_interior_stays_inside_the_box():
    # A subject that fills the whole box (as the shipped model paints the wall behind the person): the
    # interior's coarse cells reach past the box's own pixels, which must stay background.
    full, _ = _render(NovelViewConfig(enabled=True), DiscSession(radius=500.0))
    fast, s = _render(NovelViewConfig(enabled=True, interior_stride=2), DiscSession(radius=500.0))
    assert fast.rays < full.rays
    assert np.abs(fast.image.astype(int) - full.image.astype(int)).max() <= 1
    np.testing.assert_array_equal(fast.image.any(axis=-1), full.image.any(axis=-1))


def test_sparse_interior_is_really_sparse_and_never_touches_the_rim():
    big = 30.0
    full, _ = _render(NovelViewConfig(enabled=True), CheckerDiscSession(radius=big))
    fast, _ = _render(NovelViewConfig(enabled=True, interior_stride=2), CheckerDiscSession(radius=big))
    differ = np.any(fast.image != full.image, axis=-1)
    v, u = np.nonzero(differ)
    dist = np.hypot(u - CENTRE[0], v - CENTRE[1])
    assert differ.sum() > 0.3 * np.pi * big ** 2  # the 1-px checker is gone inside ...
    assert dist.max() < big - 1.5  # ... and the silhouette's rim is rendered at full resolution
    u, v = np.meshgrid(np.arange(128) - CENTRE[0], np.arange(128) - CENTRE[1])
    assert not fast.image[np.hypot(u, v) > big + 6].any()


def test_sparse_interior_with_heatmaps_and_small_or_absent_subjects():
    nv, s = _render(NovelViewConfig(enabled=True, heatmaps=True, interior_stride=2), DiscSession(radius=30.0),
                    want_heat=True)
    assert nv.heat is not None and nv.heat.max() == 1.0 and nv.heat[64, 64] == 1.0
    # A subject too small to have an interior renders exactly as without the option.
    for radius in (4.0, 0.0):
        plain, _ = _render(NovelViewConfig(enabled=True), DiscSession(radius=radius))
        sparse, _ = _render(NovelViewConfig(enabled=True, interior_stride=2), DiscSession(radius=radius))
        np.testing.assert_array_equal(plain.image, sparse.image)
        assert plain.rays == sparse.rays


def test_interior_stride_config_is_validated():
    assert NovelViewConfig(interior_stride=2).interior_pass
    assert not NovelViewConfig(stride=2, interior_stride=2).interior_pass  # no sparser than the render
    assert not NovelViewConfig(silhouette_stride=0, interior_stride=2).interior_pass  # needs the coarse pass
    for bad in (3, 16, -1, 2.0, True):
        with pytest.raises(ConfigError, match="interior_stride"):
            NovelViewConfig(interior_stride=bad)
    with pytest.raises(ConfigError, match="interior_stride"):
        NovelViewConfig(interior_stride=8, silhouette_stride=4)  # must divide the coarse cells


class TranslucentSession(DiscSession):
    """The disc at opacity 0.8 and faint fog (opacity 0.1, grey 0.3) around it: a model that dims its subject."""

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph == "volume":
            return out
        inside = out["acc"][0]
        colour = np.where(inside[:, None] > 0, out["rgb"][0], 0.3)  # what each ray hit
        acc = np.where(inside > 0, 0.8, 0.1).astype(np.float32)
        out["rgb"] = (acc[:, None] * colour)[None].astype(np.float32)  # composited over black
        out["acc"] = acc[None]
        return out


def test_opaque_at_shows_a_translucent_subject_in_its_own_colour_and_keeps_fog_faint():
    cfg = NovelViewConfig(enabled=True, silhouette_stride=0)
    want, _ = _render(cfg)  # the opaque disc
    raw, _ = _render(replace(cfg, opaque_at=1.0), TranslucentSession())
    shown, _ = _render(cfg, TranslucentSession())  # the default, 0.5
    disc = want.image[..., 0] > 0
    assert disc.sum() > 300
    assert np.abs(raw.image[disc].astype(int) - (0.8 * want.image[disc]).astype(int)).max() <= 1  # dimmed
    assert np.abs(shown.image[disc].astype(int) - want.image[disc].astype(int)).max() <= 1  # its own colour
    fog = ~disc & (raw.image[..., 0] > 0)
    assert fog.sum() > 300
    assert np.all(raw.image[fog] == round(0.1 * 0.3 * 255))
    assert np.all(shown.image[fog] == round(0.2 * 0.3 * 255))  # twice as bright at most, still faint


def test_opaque_colour_over_a_grey_background():
    from ghnerf_runtime.novel_view import opaque_colour

    colour = np.array([[0.2, 0.8, 0.4], [0.2, 0.8, 0.4], [0.9, 0.9, 0.9]])
    acc = np.array([0.9, 0.3, 0.0])
    composite = acc[:, None] * colour + (1 - acc[:, None]) * 0.5
    got = opaque_colour(composite, acc, 0.5, 0.5)
    np.testing.assert_allclose(got[0], colour[0], atol=1e-9)  # opaque enough: the colour itself
    np.testing.assert_allclose(got[1], 0.6 * colour[1] + 0.4 * 0.5, atol=1e-9)  # 0.3 / 0.5 of it
    np.testing.assert_allclose(got[2], [0.5, 0.5, 0.5], atol=1e-9)  # an empty ray is the background
    assert opaque_colour(composite, acc, 0.5, 1.0) is composite
    nan_acc = opaque_colour(composite, np.array([np.nan, 0.3, 0.0]), 0.5, 0.5)
    assert np.all(np.isfinite(nan_acc))


def test_the_tuning_scripts_opacity_floor_clears_faint_rays_and_keeps_opaque_ones():
    from benchmarks.tune_proxy_matte import cleared
    from ghnerf_runtime.novel_view import opaque_colour

    colour = np.tile([[0.2, 0.8, 0.4]], (5, 1))
    acc = np.array([0.9, 0.35, 0.2, 0.0, 1.0])
    composite = acc[:, None] * colour + (1 - acc[:, None]) * 0.5
    assert np.array_equal(cleared(composite, acc, 0.5, 0.5, 0.0), opaque_colour(composite, acc, 0.5, 0.5))
    got = cleared(composite, acc, 0.5, 0.5, 0.2)
    np.testing.assert_allclose(got[[0, 4]], colour[[0, 4]], atol=1e-9)  # opaque: the colour itself
    np.testing.assert_allclose(got[1], 0.5 * colour[1] + 0.5 * 0.5, atol=1e-9)  # halfway up the ramp
    np.testing.assert_allclose(got[2:4], 0.5, atol=1e-9)  # at or under the floor: the background
    assert np.all(np.isfinite(cleared(composite, np.array([np.nan, 0.3, 0.0, 1e-12, 1.0]), 0.5, 0.5, 0.2)))


def test_opaque_at_is_validated():
    assert NovelViewConfig().opaque_at == 0.5
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ConfigError, match="opaque_at"):
            NovelViewConfig(opaque_at=bad)


@pytest.mark.parametrize("rays_in_box_only", [True, False])
def test_a_camera_facing_away_from_the_subject_renders_the_background_without_running_the_graphs(rays_in_box_only):
    """The box wholly behind the requested camera: no near/far of it exists (near_far_from_box refuses it), so
    nothing is rendered, not a 1 mm sweep at the near plane over the full grid."""
    centre = BOX.mean(axis=0)
    R, t = look_at((0.0, -0.9, 0.0), (0.0, -0.9, -1.0))  # at the box's height, looking away from it
    away = Camera("novel", 128, 128, intrinsics_from_fov(128, 128, 40.0), np.zeros(5), R, t)
    assert (away.R @ centre + away.t)[2] < 0  # the subject is behind it
    session = DiscSession()
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    config = NovelViewConfig(enabled=True, rays_in_box_only=rays_in_box_only)
    nv = render_novel_view(session, env, away, BOX, config)
    assert session.rays == [] and nv.rays == 0
    assert not nv.image.any() and not nv.depth.any()


def test_a_non_finite_subject_box_is_an_error_not_an_empty_view():
    from ghnerf_runtime.errors import GeometryError
    box = BOX.copy()
    box[0, 0] = np.nan
    with pytest.raises(GeometryError, match="not finite"):
        _render_box(box)


def _render_box(box):
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    return render_novel_view(DiscSession(), env, _camera(), box, NovelViewConfig(enabled=True))


class NaNGreySession(DiscSession):
    """A model over a grey background (0.5) whose rays left of the disc's centre come back NaN."""

    def __init__(self):
        super().__init__(opaque_background=True)
        self.contract = replace(self.contract, background=0.5)

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph != "volume":
            uv = feeds["ray_uv"][0]
            inside = np.linalg.norm(uv - CENTRE, axis=-1) <= self.radius
            out["rgb"] = np.where(inside[:, None], out["rgb"][0], 0.5)[None].astype(np.float32)
            out["rgb"][0, uv[:, 0] < CENTRE[0]] = np.nan
        return out


@pytest.mark.parametrize("stride", [1, 2])
def test_a_nan_ray_is_drawn_as_the_background_not_black(stride):
    # nan_to_num(nan=0.0) drew it black: a black half-disc and black rays round it on a grey background
    nv, _ = _render(NovelViewConfig(enabled=True, stride=stride, silhouette_stride=0), NaNGreySession())
    left = np.arange(128) < CENTRE[0] - stride
    assert np.all(nv.image[:, left] == 128)  # round(0.5 * 255)
    assert nv.image[:, ~left].min() > 0 and np.isfinite(nv.depth).all()


def test_the_heatmap_overlay_rounds_its_blend_to_the_nearest_level():
    # astype(uint8) truncated: every blended pixel came out up to one level darker, on average half of one
    import cv2

    from ghnerf_runtime.novel_view import heatmap_overlay

    image = np.random.default_rng(0).integers(0, 256, (32, 32, 3)).astype(np.uint8)
    heat = np.linspace(0.0, 1.0, 32 * 32, dtype=np.float32).reshape(32, 32)
    colour = cv2.applyColorMap((heat * 255).astype(np.uint8), cv2.COLORMAP_JET).astype(np.float64)
    alpha = 0.5 * heat.astype(np.float64)[..., None]
    exact = image * (1 - alpha) + colour * alpha
    got = heatmap_overlay(image, heat)
    assert np.abs(got - exact).max() <= 0.5 + 1e-3
    assert np.array_equal(got[0, 0], image[0, 0])  # no heat: the picture itself


# ------------------------------------------------------------------ extremes (session 50's numerical review)
class FailedRaySession(DiscSession):
    """The disc, with the rays within 0.75 px of the centre pixel (64.5, 64.5) failed: colour and heatmaps NaN,
    depth +inf (``failed=True``), or rendered as an empty ray would be: background colour, heat 0, depth 0."""

    def __init__(self, failed: bool):
        super().__init__()
        self.failed = failed

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph == "volume":
            return out
        bad = np.all(np.abs(feeds["ray_uv"][0] - 64.5) < 0.75, axis=-1)
        out = {k: v.astype(np.float32) for k, v in out.items()}
        out["rgb"][0, bad] = np.nan if self.failed else self.contract.background
        out["depth"][0, bad] = np.inf if self.failed else 0.0
        if "heatmaps" in out:
            out["heatmaps"][0, bad] = np.nan if self.failed else 0.0
        return out


@pytest.mark.parametrize("config", [
    NovelViewConfig(enabled=True, stride=2, silhouette_stride=0),  # upsampled x2
    NovelViewConfig(enabled=True, stride=1, silhouette_stride=4, interior_stride=2),  # the interior filled in
    NovelViewConfig(enabled=True, stride=1, silhouette_stride=0),
], ids=["stride2", "interior", "stride1"])
def test_a_failed_ray_renders_as_an_empty_ray_not_a_hole_around_it(config):
    """A NaN ray shows what a ray that rendered nothing shows, and only where that ray would: before, the NaN
    went through the bilinear upsampling (heat at stride 2) and the interior's filling (every channel), which
    spread it to each pixel it reached (16 pixels of heat 0 at stride 2), and an inf depth came out as 3.4e38."""
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    failed, empty = (render_novel_view(FailedRaySession(f), env, _camera(), BOX, config, want_heat=True)
                     for f in (True, False))
    assert failed.rays == empty.rays
    assert np.array_equal(failed.image, empty.image)
    assert np.array_equal(failed.depth, empty.depth) and failed.depth.max() == pytest.approx(3.0)
    assert np.array_equal(failed.heat, empty.heat)
    centre = np.hypot(*(np.mgrid[:128, :128] - 64.5)) <= 3.0  # the failed ray's neighbourhood, inside the disc
    assert np.count_nonzero(failed.heat[centre] == 0) <= 4  # the four failed pixels at stride 1; none upsampled


class OutOfRangeHeatSession(DiscSession):
    """The disc, its heatmaps answered ``value`` inside it on every joint: a finite answer past [0, 1] that no
    sigmoid gives (a graph that ends otherwise, a corrupt file)."""

    def __init__(self, value: float):
        super().__init__()
        self.value = value

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if "heatmaps" in out:
            out["heatmaps"] = np.where(out["heatmaps"] > 0, np.float32(self.value), np.float32(0.0))
        return out


@pytest.mark.parametrize("config", [
    NovelViewConfig(enabled=True, stride=2, silhouette_stride=0),
    NovelViewConfig(enabled=True, stride=1, silhouette_stride=4, interior_stride=2),
], ids=["stride2", "interior"])
@pytest.mark.parametrize("value", [1e30, 1.5, -1e30])
def test_novel_view_heat_stays_in_the_unit_range_whatever_the_graph_answers(config, value):
    """``NovelView.heat`` is the max over joints of sigmoid responses, so in [0, 1] (the colour is clipped
    the same way, and the keypoint path clips the same values). Only NaN and inf were replaced: a finite
    answer past the range (1e30, -1e30) came out as it was, and the upsampling and interior filling spread it."""
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    got = render_novel_view(OutOfRangeHeatSession(value), env, _camera(), BOX, config, want_heat=True)
    disc = render_novel_view(DiscSession(), env, _camera(), BOX, config, want_heat=True)  # heat 1 in the disc
    assert disc.heat.max() == 1.0 and np.isfinite(got.heat).all()
    # past 1: the disc at 1, as a response of 1 shows; below 0: no heat at all
    assert np.array_equal(got.heat, disc.heat if value > 0 else np.zeros_like(disc.heat))


def _diagonal_drawn(image, start, n):
    """Whether the limb's green runs down the diagonal from ``start`` (past the joint's red dot) for ``n`` pixels."""
    return all(image[start[1] + k, start[0] + k, 1] > 0 for k in range(3, n))


@pytest.mark.parametrize("far", [1e3, 1e8, 1e18])
@pytest.mark.parametrize("joints", [(1, 0), (15, 0)], ids=["far joint last", "far joint first"])
def test_a_limb_to_a_joint_far_off_the_picture_is_cut_at_the_edge_not_left_out(far, joints):
    """A close view whose joint lies beyond the drawing window (three times the picture) still shows the limb
    towards it, the same line however far the joint is (each cut reckoned from the nearer end: from the far
    end, 1e18 px swallowed the near end's digits). Before, the limb was left out."""
    from ghnerf_runtime.novel_view import draw_skeleton

    near_joint, far_joint = joints  # limbs (1, 0) Neck-Nose and (0, 15) Nose-REye: the far joint at either end
    uv, valid = np.zeros((25, 2)), np.zeros(25, bool)
    uv[near_joint], uv[far_joint] = (32.0, 16.0), (32.0 + far, 16.0 + far)  # down the diagonal
    valid[[near_joint, far_joint]] = True
    out = draw_skeleton(np.zeros((64, 64, 3), np.uint8), uv, valid)
    assert _diagonal_drawn(out, (32, 16), 32)  # to the picture's edge (63, 47)
    lit = np.argwhere(out[..., 1] > 0)
    assert np.abs((lit[:, 1] - 32) - (lit[:, 0] - 16)).max() <= 2  # and only along the diagonal
    uv[far_joint] = (128.0, 112.0)  # the cut point itself (the window's edge): the same picture
    assert np.array_equal(out, draw_skeleton(np.zeros((64, 64, 3), np.uint8), uv, valid))


def test_a_joint_no_pixel_shows_is_left_out_of_the_skeleton_not_drawn_at_the_corner():
    """A joint 1e-10 m in front of the camera plane has no pixel (``Camera.project``: NaN). The estimator turned
    the NaN into pixel (0, 0) and drew the joint and its limbs there."""
    from ghnerf_runtime.novel_view import draw_skeleton, skeleton_overlay

    cam = _camera()
    points, valid = np.zeros((25, 3)), np.zeros(25, bool)
    points[1] = BOX.mean(axis=0)  # the neck, in view
    points[0] = cam.center + 1e-10 * cam.R[2] + 0.3 * cam.R[0]  # the nose, on the camera plane
    valid[[0, 1]] = True
    assert 0 < cam.to_camera(points[0])[2] <= 1e-9 and np.isnan(cam.project(points[0], distort=False)[0]).all()
    image = np.zeros((128, 128, 3), np.uint8)
    out = skeleton_overlay(image, cam, points, valid)
    assert not out[:8, :8].any()  # nothing at the corner
    uv, _ = cam.project(points[1], distort=False)
    only_neck = np.zeros((25, 2))
    only_neck[1] = uv
    assert np.array_equal(out, draw_skeleton(image, only_neck, np.arange(25) == 1))


@pytest.mark.parametrize("weight", [1.5, -0.5, float("nan")])
def test_the_heatmap_overlay_refuses_a_weight_outside_0_1(weight):
    # 1.5 over a white-ish picture: 200 * -0.5 + 0 * 1.5 = -100 wrapped round to 156 in uint8
    from ghnerf_runtime.novel_view import heatmap_overlay

    with pytest.raises(ValueError, match="weight"):
        heatmap_overlay(np.full((4, 4, 3), 200, np.uint8), np.ones((4, 4), np.float32), weight)
    full = heatmap_overlay(np.full((4, 4, 3), 200, np.uint8), np.ones((4, 4), np.float32), 1.0)
    assert full[0, 0].tolist() == [0, 0, 128]  # weight 1: the colour map itself (JET at 1: dark red, BGR)


@pytest.mark.parametrize("alpha", [None, "0.5", True, [0.5]])
def test_a_request_whose_alpha_is_not_a_number_is_a_geometry_error_naming_the_field(alpha):
    """np.isfinite raised a bare TypeError for None or a string, and True passed as alpha 1."""
    from ghnerf_runtime.errors import GeometryError
    from ghnerf_runtime.novel_view import NovelViewRequest
    with pytest.raises(GeometryError, match=r"NovelViewRequest\.alpha must be a number"):
        NovelViewRequest(alpha=alpha)
    assert NovelViewRequest(alpha=np.float32(0.25)).alpha == 0.25 and NovelViewRequest(alpha=1).alpha == 1
    assert NovelViewRequest(alpha=None, camera=_camera()).camera is not None  # alpha unused with a camera


@pytest.mark.parametrize("camera", [{"R": np.eye(3)}, "left", np.eye(3)])
def test_a_request_whose_camera_is_not_a_camera_is_refused_when_made(camera):
    """It was accepted and failed later, in the estimator's worker, as an AttributeError."""
    from ghnerf_runtime.errors import GeometryError
    from ghnerf_runtime.novel_view import NovelViewRequest
    with pytest.raises(GeometryError, match=r"NovelViewRequest\.camera must be a Camera or None"):
        NovelViewRequest(camera=camera)


# ------------------------------------------------------------------ numerical extremes (session 53)
@pytest.mark.parametrize("offset", [1e200, 1e30, 2e4])
def test_a_subject_box_beyond_float32_depths_is_an_error_naming_it_not_an_inf_near_far(offset):
    """A box around 1e200 m gave near/far of inf (float32 overflow), 1e30 m near == far (the 1 mm floor lost):
    the graphs ran on them. Now a DepthRangeError names the box and how far it reaches, and nothing runs."""
    from ghnerf_runtime.contract import MAX_DEPTH_M
    from ghnerf_runtime.errors import DepthRangeError
    box = BOX + np.array([0.0, 0.0, offset])
    session = DiscSession()
    env = {"images": np.zeros((2, 3, 128, 128), np.float32)}
    reach = offset + BOX[1, 2] + 0.1  # the far corner of the box grown by the margin
    said = re.escape(f"reaches {reach:.6g} m from camera 'novel', farther than the {MAX_DEPTH_M:g} m (MAX_DEPTH_M)")
    with pytest.raises(DepthRangeError, match=said):
        render_novel_view(session, env, _camera(), box, NovelViewConfig(enabled=True))
    assert session.rays == []


def test_near_far_holds_its_floor_in_float32_up_to_the_limit_and_refuses_past_it():
    from ghnerf_runtime.contract import MAX_DEPTH_M, near_far_from_box
    from ghnerf_runtime.errors import DepthRangeError
    from ghnerf_runtime.tracking import box_corners
    cam = _camera()
    thin = np.array([[0.0, -0.9, 0.0], [0.0, -0.9, 0.0]])
    deep = thin + [0.0, 0.0, MAX_DEPTH_M - 1.0]  # a point box 1 m inside the limit: far = near + 1 mm
    near, far = near_far_from_box(cam, box_corners(deep), margin=0.0)
    assert np.isfinite([near, far]).all() and far > near
    wide = np.array([[-1e300, -0.9, 2.0], [1e300, -0.9, 3.0]])  # in front, but wider than anything rendered
    with pytest.raises(DepthRangeError, match="MAX_DEPTH_M"):
        near_far_from_box(cam, box_corners(wide), margin=0.0)
    # a camera turned 45 degrees: the depth of (1.7e308, y, 1.7e308) is 2.4e308, past float64 (inf, not "behind")
    R, t = look_at((0.0, 0.0, 0.0), (1.0, 0.0, 1.0))
    turned = Camera("turned", 128, 128, intrinsics_from_fov(128, 128, 40.0), np.zeros(5), R, t)
    huge = np.array([[1.6e308, -0.9, 1.6e308], [1.7e308, -0.9, 1.7e308]])
    with pytest.raises(DepthRangeError, match="reaches inf m from camera 'turned'"):
        near_far_from_box(turned, box_corners(huge), margin=0.0)


def test_a_far_box_wholly_behind_the_camera_is_still_an_empty_view():
    """Behind comes first: nothing of such a box is in front, so it renders nothing, as a near one behind does."""
    box = BOX - np.array([0.0, 0.0, 1e200])
    session = DiscSession()
    nv = render_novel_view(session, {"images": np.zeros((2, 3, 128, 128), np.float32)}, _camera(), box,
                           NovelViewConfig(enabled=True))
    assert session.rays == [] and nv.rays == 0 and not nv.image.any()
