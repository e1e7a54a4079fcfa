"""``tracking.cold_tiles_below_share``: a cold pair that finds nobody, on a rig whose cold crop (the whole working
volume) draws a person too small for the model, searches one of the volume's tiles (docs/runtime.md, "Cold tiles").

The oracle here is blind to people under :data:`BLIND_BELOW_PX` model pixels tall, as the shipped model, trained on
people of about 63 such pixels and more, misses those of 51 (docs/rig-file.md, "A person who does not fit the view").
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_runtime_common import OracleSession, edge128_contract
from benchmarks.empty_rooms import empty_room_pair, scene_with_screen, scene_without_person, with_screen
from benchmarks.measure_baseline import lifted
from ghnerf_runtime.config import ConfigError, EstimatorConfig, RoiConfig, TrackingConfig
from ghnerf_runtime.estimator import Estimator
from ghnerf_runtime.rig_file import load_rig
from ghnerf_runtime.scene_change import CALM_AFTER_PASSES, ONE_VIEW_NOT_VAIN_PAIRS, RESTLESS_AFTER_WAKES, pair_copies
from ghnerf_runtime.tracking import COLD_TILE_SPLITS, cold_person_share, volume_regions, volume_tiles
from tests.ghnerf_runtime.sim_takes import pair_images
from tests.one_camera import seen_by

sim = pytest.importorskip("drivers.sim")

EXAMPLE_RIG = Path(__file__).resolve().parents[2] / "docs" / "examples" / "rig.json"
#: the blind oracle's bound: a person shorter than this in either crop, model pixels, is not seen
BLIND_BELOW_PX = 60.0


class SmallPeopleBlindOracle(OracleSession):
    """The oracle, answering no heatmap where the person is under :data:`BLIND_BELOW_PX` model pixels tall in a
    source crop (their joints' vertical extent through ``src_P``)."""

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph in ("encoder", "human") and self.truth is not None and self._too_small(feeds["src_P"]):
            out["encoder_heatmaps"] = np.zeros_like(out["encoder_heatmaps"])
        return out

    def _too_small(self, src_P) -> bool:
        homog = np.concatenate([self.truth, np.ones((len(self.truth), 1))], axis=1)
        heights = []
        for P in np.asarray(src_P, np.float64):
            p = homog @ P.T
            v = p[:, 1] / p[:, 2]
            heights.append(float(v.max() - v.min()))
        return min(heights) < BLIND_BELOW_PX


def blind_estimator(rig, config: EstimatorConfig | None = None) -> tuple[SmallPeopleBlindOracle, Estimator]:
    """A :class:`SmallPeopleBlindOracle` and an estimator on it through ``rig`` (the runtime's defaults unless
    ``config``)."""
    oracle = SmallPeopleBlindOracle(edge128_contract())
    return oracle, Estimator(oracle, rig, EstimatorConfig() if config is None else config)


@pytest.fixture(scope="module")
def example_rig():
    return load_rig(EXAMPLE_RIG, warn=False)


@pytest.fixture(scope="module")
def far_person(example_rig):
    """One frame pair of a person standing 4 m ahead, 0.8 m left, through the example rig, and their joints: 38 model
    pixels tall through the whole volume's crop, 52-56 through the near tiles', 68 through the far ones'."""
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(-0.8, 4.0)))
    images = pair_images(scene, example_rig, 0.0)
    return images, scene.joints_3d(0.0)


def test_the_example_rigs_cold_crop_draws_a_person_small_and_its_tiles_larger(example_rig):
    whole = cold_person_share(example_rig, volume_regions(example_rig, RoiConfig()))
    tiles = volume_tiles(example_rig, RoiConfig())
    assert 0.38 < whole < 0.42  # 51 of 128 model pixels (docs/rig-file.md)
    assert len(tiles) == COLD_TILE_SPLITS[0] * COLD_TILE_SPLITS[1]
    for tile in tiles:
        assert all(t.size < w.size for t, w in zip(tile.rois, volume_regions(example_rig, RoiConfig()).rois))
        assert np.all(tile.box[0] >= example_rig.volume.min_corner)
        assert np.all(tile.box[1] <= example_rig.volume.max_corner)
    # together they cover the volume
    lo, hi = np.min([t.box[0] for t in tiles], axis=0), np.max([t.box[1] for t in tiles], axis=0)
    np.testing.assert_allclose(lo, example_rig.volume.min_corner)
    np.testing.assert_allclose(hi, example_rig.volume.max_corner)


def test_a_person_too_small_in_the_cold_crop_is_found_through_a_tile_then_tracked(example_rig, far_person):
    images, joints = far_person
    oracle, est = blind_estimator(example_rig)
    oracle.set_truth(joints)
    results = [est.estimate(images) for _ in range(6)]
    found = [int((~r.missing).sum()) for r in results]
    # before the tiles, the whole volume's crop drew them at 38 model pixels: no pair found them
    assert max(found) > 0, found
    first = next(i for i, n in enumerate(found) if n > 0)
    assert first == 1  # one tile a pair: the near left one, then the far left one
    assert all(r.tracked for r in results[first:])  # refined on the subject's crop, then tracked
    assert est.cold_tiles_found == 1 and est.cold_tile_passes == first + 1
    err = np.linalg.norm(results[-1].joints_3d - joints, axis=1)[~results[-1].missing]
    assert np.median(err) < 0.05


class OneViewOracle(SmallPeopleBlindOracle):
    """The blind oracle with the second camera's heatmaps empty: a person only the first camera shows."""

    def run(self, graph, feeds):
        out = super().run(graph, feeds)
        if graph in ("encoder", "human"):
            out["encoder_heatmaps"] = out["encoder_heatmaps"].copy()
            out["encoder_heatmaps"][1] = 0.0
        return out


def test_a_person_a_tile_shows_one_camera_only_is_the_pair_s_answer(example_rig, far_person):
    """A tile pass seeing the person in one view was thrown away (the pair reported the whole volume's nothing, and
    the next tile was searched next) while the tracker followed that view: now it is the pair's answer, the tile
    that saw them kept first."""
    images, joints = far_person
    oracle = OneViewOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    oracle.set_truth(joints)
    results = [est.estimate(images) for _ in range(2)]
    first = results[1]  # the near left tile draws them too small; the far left one shows them to camera 0
    assert first.single_view == example_rig.pair[0].name
    assert not first.missing_2d[first.single_view].all()
    assert est.cold_tiles_found == 1 and est._next_tile == 1


def test_an_empty_room_pays_one_tile_pass_a_pair(example_rig):
    images = empty_room_pair(example_rig, 11, 0.2)

    def encoder_runs(below: float) -> tuple[int, Estimator]:
        config = EstimatorConfig(tracking=TrackingConfig(cold_tiles_below_share=below))
        oracle, est = blind_estimator(example_rig, config)
        oracle.set_truth(None)
        for _ in range(3):
            assert est.estimate(images).missing.all()
        return sum(oracle.run_counts.get(g, 0) for g in ("encoder", "human")), est

    plain, off = encoder_runs(0.0)
    tiled, on = encoder_runs(0.47)
    assert off.cold_tile_passes == 0 and on.cold_tile_passes == 3
    assert tiled == plain + 3
    assert on._next_tile == 3  # one tile after the other


def test_a_rig_whose_cold_crop_frames_a_person_has_no_tiles():
    rig = sim.RigPlacement().build()  # the simulator's default: 0.52, 67 of 128 model pixels
    oracle, est = blind_estimator(rig)
    assert est._cold_tiles == ()
    oracle.set_truth(None)
    est.estimate(empty_room_pair(rig, 11, 0.2))
    assert est.cold_tile_passes == 0


@pytest.mark.parametrize("value", [-0.1, float("nan"), 1.5])
def test_cold_tiles_below_share_out_of_range_is_refused(value):
    with pytest.raises(ConfigError, match="cold_tiles_below_share"):
        TrackingConfig(cold_tiles_below_share=value)


def test_a_lost_track_is_retried_cold_then_searched_from_the_tile_that_found_the_subject(example_rig, far_person):
    """docs/runtime.md, "Cold tiles": a tracked pair that loses its subject is retried cold (``tracking.retry_cold``)
    and, finding nobody there either, searches a tile, first the one that found the subject."""
    images, joints = far_person
    oracle, est = blind_estimator(example_rig)
    oracle.set_truth(joints)
    for _ in range(3):
        est.estimate(images)
    assert est.tracker.track is not None and est.cold_tiles_found == 1
    found_in, passes = est._next_tile, est.cold_tile_passes
    oracle.set_truth(None)  # the subject has left: the tracked crop, the working volume's and the tile show nobody
    assert est.estimate(empty_room_pair(example_rig, 11, 0.2)).missing.all()
    assert est.cold_tile_passes == passes + 1 and est.cold_tiles_found == 1
    assert est._next_tile == found_in + 1  # that tile was searched, the next one is searched next


def test_an_empty_room_rests_the_tiles_after_a_whole_round(example_rig):
    """After the four tiles found nobody in a row, only every ``cold_tiles_rest_every``-th cold pair searches."""
    images = empty_room_pair(example_rig, 11, 0.2)
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=3)))
    oracle.set_truth(None)
    passes = []
    for _ in range(13):
        assert est.estimate(images).missing.all()
        passes.append(est.cold_tile_passes)
    # pairs 1-4 search each tile once; then pairs 7, 10, 13 (every 3rd)
    assert passes == [1, 2, 3, 4, 4, 4, 5, 5, 5, 6, 6, 6, 7]


def test_a_person_walking_into_a_resting_room_is_found_and_tracked(example_rig, far_person):
    images, joints = far_person
    empty = empty_room_pair(example_rig, 11, 0.2)
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=3)))
    oracle.set_truth(None)
    for _ in range(5):
        est.estimate(empty)
    assert est._tile_rest_wait > 0  # resting
    oracle.set_truth(joints)
    found = [int((~est.estimate(images).missing).sum()) for _ in range(12)]
    first = next(i for i, n in enumerate(found) if n > 0)
    assert first < 12 and all(n > 0 for n in found[first:])
    assert est._tiles_missed == 0 and est._tile_rest_wait == 0  # awake again


def test_a_reset_wakes_resting_tiles(example_rig):
    _, est = blind_estimator(example_rig)
    est._tiles_missed, est._tile_rest_wait = 4, 3
    est.reset()
    assert est._tiles_missed == 0 and est._tile_rest_wait == 0
    assert est._tiles_awake(empty_room_pair(example_rig, 11, 0.2))


@pytest.mark.parametrize("value", [0, -1, 1.5])
def test_cold_tiles_rest_every_out_of_range_is_refused(value):
    with pytest.raises(ConfigError, match="cold_tiles_rest_every"):
        TrackingConfig(cold_tiles_rest_every=value)


def test_a_person_the_whole_volume_finds_wakes_the_tiles(example_rig):
    """A resting estimator whose whole-volume pass finds someone (near enough to be drawn large) searches the tiles on
    every cold pair again once they are gone."""
    near = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 2.0)))
    near_images = pair_images(near, example_rig, 0.0)
    empty = empty_room_pair(example_rig, 11, 0.2)
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=3)))
    oracle.set_truth(None)
    for _ in range(5):
        est.estimate(empty)
    assert est._tile_rest_wait > 0
    oracle.set_truth(near.joints_3d(0.0))
    passes = est.cold_tile_passes
    assert not est.estimate(near_images).missing.all()
    assert est.cold_tile_passes == passes  # found by the whole volume's crop, no tile needed
    oracle.set_truth(None)
    for _ in range(2):
        est.estimate(empty)
    assert est.cold_tile_passes == passes + 2  # awake: one tile a pair again


def test_reset_keeps_every_counter_and_says_which_it_keeps(example_rig):
    """The estimator's counters (its public ints but its sizes) are statistics over its life: ``reset()`` keeps them,
    the cold tiles' with the turn search's, and its docstring names each (it named two and an ellipsis, and
    docs/runtime.md none of the cold tiles')."""
    oracle, est = blind_estimator(example_rig)
    oracle.set_truth(None)
    est.estimate(empty_room_pair(example_rig, 11, 0.2))
    counters = sorted(name for name, value in vars(est).items()
                      if not name.startswith("_") and type(value) is int and name not in ("size", "grid"))
    assert {"cold_tile_passes", "cold_tiles_found", "turns_refused"} <= set(counters)
    for k, name in enumerate(counters):
        setattr(est, name, k + 1)
    est.reset()
    assert [getattr(est, name) for name in counters] == list(range(1, len(counters) + 1))
    assert [name for name in counters if f"``{name}``" not in Estimator.reset.__doc__] == []
    runtime_doc = (Path(__file__).resolve().parents[2] / "docs" / "runtime.md").read_text(encoding="utf-8")
    assert [name for name in counters if f"{name}`" not in runtime_doc] == []  # `name` or `Estimator.name`


# ------------------------------------------------------------------ tracking.cold_tiles_wake_levels
def far_scene_room(example_rig, times, sensor=None) -> list[tuple[np.ndarray, ...]]:
    """:func:`far_person`'s room with nobody in it, one pair at each of ``times`` (its own sensor noise each), through
    ``sensor`` where given (the scene's default otherwise)."""
    config = sim.SceneConfig(seed=11, motion="wave", position_xz=(-0.8, 4.0))
    scene = sim.SimScene(config if sensor is None else dataclasses.replace(config, sensor=sensor))
    return [scene_without_person(scene, example_rig.pair, t) for t in times]


def resting_estimator(example_rig, rest_every: int, wake_levels=6.0):
    """A blind oracle and an estimator through ``example_rig`` that has searched all four tiles of :func:`far_person`'s
    empty room once and rests now."""
    config = EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=rest_every,
                                                     cold_tiles_wake_levels=wake_levels))
    oracle, est = blind_estimator(example_rig, config)
    oracle.set_truth(None)
    for images in far_scene_room(example_rig, [1.0 + i / 30.0 for i in range(5)]):
        assert est.estimate(images).missing.all()
    assert est._tile_rest_wait > 0 and est.cold_tile_passes == 4  # resting
    return oracle, est


def test_a_walk_in_wakes_resting_tiles_and_is_found_on_the_next_pair(example_rig, far_person):
    """A resting search skipped the tile pass on the pair the person walked in and on the next, and reached their tile
    (the second, far left) only on pair 16 after (rest 8); the scene change wakes it on the walk-in pair itself."""
    images, joints = far_person
    oracle, est = resting_estimator(example_rig, rest_every=8)
    oracle.set_truth(joints)
    walk_in = est.estimate(images)  # the near left tile draws them too small (52-56 model pixels): not yet
    assert walk_in.missing.all()
    assert est.cold_tile_wakes == 1 and est.cold_tile_passes == 5
    found = est.estimate(images)
    assert not found.missing.all() and est.cold_tiles_found == 1  # the far left tile, on the next pair


@pytest.mark.parametrize("off", [0, None])
def test_wake_levels_0_or_none_never_wake(example_rig, far_person, off):
    images, joints = far_person
    oracle, est = resting_estimator(example_rig, rest_every=8, wake_levels=off)
    oracle.set_truth(joints)
    assert est.estimate(images).missing.all()
    assert est.cold_tile_wakes == 0 and est.cold_tile_passes == 4  # rests, as before the wake-up


def test_sensor_noise_and_lighting_drift_do_not_wake_resting_tiles(example_rig):
    """An empty room through a noisy sensor (read noise 4 levels, shot noise 0.5, exposure jitter 0.05 stops: the
    top of ``random_scene``'s draws) whose light brightens by 0.5 % a pair (15 % over the run) rests as with no
    wake-up: every 3rd pair searches."""
    noisy = sim.SensorModel(read_noise=4.0, shot_noise=0.5, exposure_jitter=0.05)
    pairs = far_scene_room(example_rig, [1.0 + i / 30.0 for i in range(30)], noisy)
    config = EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=3))
    oracle, est = blind_estimator(example_rig, config)
    oracle.set_truth(None)
    passes = []
    for i, images in enumerate(pairs):
        drifted = [np.clip(im * (1.0 + 0.005 * i), 0, 255).astype(np.uint8) for im in images]
        assert est.estimate(drifted).missing.all()
        passes.append(est.cold_tile_passes)
    assert est.cold_tile_wakes == 0
    assert passes == [1, 2, 3, 4] + [4 + (i + 1) // 3 for i in range(26)]


FAR_ROOM = sim.SceneConfig(seed=11, motion="wave", position_xz=(-0.8, 4.0))


def screen_room(example_rig, times) -> list[tuple[np.ndarray, ...]]:
    """:func:`far_person`'s room with nobody in it and a screen playing (a new picture each pair), at ``times``."""
    scene = sim.SimScene(FAR_ROOM)
    return [scene_with_screen(scene, example_rig.pair, t) for t in times]


def run_screen_room(est, example_rig, pairs: int) -> tuple[list[int], list[int]]:
    """The tile passes and the wakes so far after each of ``pairs`` pairs of :func:`screen_room` through ``est``
    (nobody found)."""
    passes, wakes = [], []
    for images in screen_room(example_rig, [1.0 + i / 30.0 for i in range(pairs)]):
        assert est.estimate(images).missing.all()
        passes.append(est.cold_tile_passes)
        wakes.append(est.cold_tile_wakes)
    return passes, wakes


def test_a_screen_playing_in_an_empty_room_stops_waking_the_rest(example_rig):
    """A screen changes its cells every pair: each rest woke the search, whose round found nobody, and the tiles
    searched almost every pair (14 wakes in 60 pairs). Its cells wake :data:`RESTLESS_AFTER_WAKES`
    searches in vain, with their neighbours (the screen's edges) they wake no more: the rest holds."""
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    passes, wakes = run_screen_room(est, example_rig, 60)
    assert RESTLESS_AFTER_WAKES <= wakes[-1] <= 5
    assert wakes[-24] == wakes[-1]  # no wake in the last 24 pairs
    assert passes[-1] - passes[-25] == 6  # every 4th pair searches


def test_a_walk_in_wakes_a_rest_the_screen_no_longer_wakes(example_rig, far_person):
    """The screen's cells are ignored for waking, the rest of the picture is not: the far person walking into the
    room (left of the frame, the screen on the right) wakes the search and is found on the next pair, as without
    the screen."""
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=8)))
    oracle.set_truth(None)
    _, wakes = run_screen_room(est, example_rig, 60)
    assert wakes[-24] == wakes[-1] and est._tile_rest_wait > 0  # resting, the screen ignored
    _, joints = far_person
    scene = sim.SimScene(FAR_ROOM)
    t = 1.0 + 60 / 30.0
    walked_in = [scene.capture(with_screen(scene.renderer.render(scene.posed(0.0), cam, with_truth=False)[0],
                                           cam.name, t), cam, t) for cam in example_rig.pair]
    oracle.set_truth(joints)
    assert est.estimate(walked_in).missing.all()  # the near left tile draws them too small: not yet
    assert est.cold_tile_wakes == wakes[-1] + 1
    assert not est.estimate(walked_in).missing.all()  # the far left tile, on the next pair


def test_a_reset_forgets_the_restless_cells(example_rig):
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    run_screen_room(est, example_rig, 24)
    assert est._restless_cells() is not None and any(m.any() for m in est._restless_cells())
    est.reset()
    assert est._restless_cells() is None


@pytest.mark.parametrize("value", [-1.0, float("nan"), 300.0, "6", True])
def test_cold_tiles_wake_levels_out_of_range_is_refused(value):
    with pytest.raises(ConfigError, match="cold_tiles_wake_levels"):
        TrackingConfig(cold_tiles_wake_levels=value)


def test_a_screen_switched_off_wakes_the_rest_again_when_it_plays(example_rig):
    """Restless cells calm down: once the screen is off (its cells still over :data:`CALM_AFTER_PASSES` tile passes
    in a row, a pass every 4th pair), nothing is ignored any more, and the screen playing again wakes the rest, as
    anyone walking in there would (without the calming, a long-running device stayed blind in those cells until a reset)."""
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    run_screen_room(est, example_rig, 60)
    assert any(m.any() for m in est._restless_cells())
    # the same room, the screen dark
    off = far_scene_room(example_rig, [3.0 + i / 30.0 for i in range(4 * CALM_AFTER_PASSES + 8)])
    for images in off:
        assert est.estimate(images).missing.all()
    assert not any(m.any() for m in est._restless_cells())
    woken = est.cold_tile_wakes
    for images in screen_room(example_rig, [5.0 + i / 30.0 for i in range(4)]):
        est.estimate(images)
    assert est.cold_tile_wakes > woken


def test_tiles_that_never_rest_keep_no_scene_and_count_no_wakes(example_rig):
    """``cold_tiles_rest_every`` 1: every cold pair searches a tile, so the scene check would only cost time (about a
    quarter of a millisecond a pair) and count wakes of a rest that never happens."""
    config = EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=1, cold_tiles_wake_levels=6.0))
    oracle, est = blind_estimator(example_rig, config)
    oracle.set_truth(None)
    passes, wakes = run_screen_room(est, example_rig, 12)
    assert passes[-1] == 12 and wakes[-1] == 0
    assert est._rest_scene is None


def test_one_quiet_pass_does_not_calm_a_playing_screen(example_rig):
    """A restless cell wakes the rest again only after :data:`CALM_AFTER_PASSES` tile passes in a row that find it
    still: a screen playing random pictures leaves a cell still at one pass now and then, and when one such pass
    calmed it, the screen woke the rest again and again (the moving-room bench: 10 wakes per 100 pairs against 4).
    Here the screen is dark over one quiet pass (the pass where it went dark compares a dark frame with a lit one:
    moved), then plays again: it wakes nothing."""
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    run_screen_room(est, example_rig, 60)
    assert any(m.any() for m in est._restless_cells())
    woken, passes = est.cold_tile_wakes, est.cold_tile_passes
    for images in far_scene_room(example_rig, [3.0 + i / 30.0 for i in range(16)]):  # the screen dark
        assert est.estimate(images).missing.all()
        if est.cold_tile_passes == passes + 2:  # the pass it went dark, then one quiet pass
            break
    assert est.cold_tile_passes == passes + 2
    for images in screen_room(example_rig, [4.0 + i / 30.0 for i in range(8)]):  # playing again
        assert est.estimate(images).missing.all()
    assert est.cold_tile_wakes == woken


def test_a_wake_starts_the_restless_cells_still_passes_again(example_rig):
    """A wake (or someone seen) drops the kept scene, so the passes before it and after it are not one still run: a
    restless cell a pass short of calming is a whole :data:`CALM_AFTER_PASSES` short again after it."""
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    run_screen_room(est, example_rig, 60)
    for still in est._still_passes:
        still[:] = CALM_AFTER_PASSES - 1
    est._wake_tiles()
    assert all(not still.any() for still in est._still_passes)
    assert any(m.any() for m in est._restless_cells())


def test_a_resting_pair_builds_its_scene_copies_once(example_rig, monkeypatch):
    """The wake check and a tile pass that then finds nobody read the same pair's scene copies: built once a pair
    (every 3rd resting pair searches, so those pairs read them twice)."""
    import ghnerf_runtime.estimator as estimator_module

    built = []

    def counting_pair_copies(images):
        built.append(1)
        return pair_copies(images)

    monkeypatch.setattr(estimator_module, "pair_copies", counting_pair_copies)
    images = empty_room_pair(example_rig, 11, 0.2)
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=3)))
    oracle.set_truth(None)
    for _ in range(13):
        est.estimate(images)
    assert est.cold_tile_passes == 7 and len(built) == 13  # one a pair, not 13 + the 3 resting passes


def test_a_screen_read_as_a_person_in_one_view_still_stops_waking_the_rest(example_rig):
    """The model may read a screen's picture as a person in one view (the moving-room bench: 9 pairs in 100). Such a
    sighting on the pair after each wake cleared the wake as not in vain, so the screen's cells never grew restless
    and woke the rest again and again (10 wakes in 60 pairs, 4 in the last 24); a sighting in one view alone now
    leaves the wake to its round, which finds nobody, and the rest holds as with no sighting."""
    near = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 2.0)))
    seen = near.joints_3d(0.0)
    oracle, est = blind_estimator(example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_rest_every=4)))
    oracle.set_truth(None)
    wakes, one_view = [], 0
    for images in screen_room(example_rig, [1.0 + i / 30.0 for i in range(60)]):
        result = est.estimate(images)
        assert result.missing.all()
        one_view += result.single_view is not None
        woke = est.cold_tile_wakes > (wakes[-1] if wakes else 0)
        wakes.append(est.cold_tile_wakes)
        oracle.set_truth(seen, seen_by(np.ones((2, len(seen)), bool), 0)) if woke else oracle.set_truth(None)
    assert one_view >= RESTLESS_AFTER_WAKES  # each wake's next pair saw 'someone' in one view
    assert RESTLESS_AFTER_WAKES <= wakes[-1] <= 5
    assert wakes[-24] == wakes[-1]  # no wake in the last 24 pairs


def test_a_walk_in_seen_in_one_view_then_in_both_is_no_vain_wake(example_rig, far_person):
    """A person who wakes the rest, is seen by one camera first (through the far left tile) and then by both (the
    same tile, the other camera's view of them now clear) was found: the wake was not in vain, and once they are gone
    the round that finds nobody counts nothing against the cells they moved."""
    images, joints = far_person
    oracle, est = resting_estimator(example_rig, rest_every=8)
    oracle.set_truth(joints, seen_by(np.ones((2, len(joints)), bool), 0))
    assert est.estimate(images).missing.all()  # the walk-in wakes the rest; the near left tile draws them too small
    assert est.cold_tile_wakes == 1 and est._woke_on is not None
    assert est.estimate(images).single_view == example_rig.pair[0].name  # the far left tile, one camera
    assert est._woke_on is not None  # one view alone: the wake is still to be judged
    oracle.set_truth(joints)
    assert not est.estimate(images).missing.all()  # both cameras: found
    assert est._woke_on is None
    oracle.set_truth(None)
    for room in far_scene_room(example_rig, [2.0 + i / 30.0 for i in range(8)]):  # gone: a whole round finds nobody
        assert est.estimate(room).missing.all()
    assert est._tile_rest_wait > 0  # resting again
    assert est._vain_wakes is None


def visit_seen_by_one_camera(est, oracle, example_rig, t0: float, one_view_pairs: int,
                             step_s: float | None = None) -> list[str | None]:
    """:data:`FAR_ROOM`'s person walks in at ``t0`` seen by the left camera alone (the walk-in pair wakes the rest;
    the near left tile draws them too small, the far left tile sees them from the next pair on), stays for
    ``one_view_pairs`` pairs more and leaves: a whole round of tiles then finds nobody. Each pair's ``single_view``
    while there. ``step_s``: the visit's pairs are given capture times that far apart (None: no times, 30 a second
    in the scene)."""
    scene = sim.SimScene(FAR_ROOM)
    seen = []
    for i in range(1 + one_view_pairs):
        t = t0 + i * (1 / 30.0 if step_s is None else step_s)
        joints = scene.joints_3d(t)
        oracle.set_truth(joints, seen_by(np.ones((2, len(joints)), bool), 0))
        stamp = None if step_s is None else t
        seen.append(est.estimate(pair_images(scene, example_rig, t), timestamp_s=stamp).single_view)
    oracle.set_truth(None)
    for room in far_scene_room(example_rig, [t0 + 0.5 + i / 30.0 for i in range(8)]):
        assert est.estimate(room).missing.all()
    assert est._tile_rest_wait > 0  # resting again
    return seen


def test_a_person_who_stays_in_one_camera_s_view_is_no_vain_wake(example_rig):
    """A person seen by one camera alone over a whole round's pairs was someone, not a screen's picture read as a
    person on a pair: the wake was not in vain. Their cells counted it (25 of each camera's), and after two such visits
    they were restless: the person walking in there again woke nothing, the search waiting for the rest's own pass."""
    oracle, est = resting_estimator(example_rig, rest_every=8)
    for visit in range(RESTLESS_AFTER_WAKES):
        seen = visit_seen_by_one_camera(est, oracle, example_rig, 3.0 + visit, ONE_VIEW_NOT_VAIN_PAIRS)
        assert seen[1:] == [example_rig.pair[0].name] * ONE_VIEW_NOT_VAIN_PAIRS
        assert est._vain_wakes is None
    wakes = est.cold_tile_wakes
    visit_seen_by_one_camera(est, oracle, example_rig, 5.0, 0)
    assert est.cold_tile_wakes == wakes + 1  # the walk-in pair woke the rest


def test_a_person_in_one_view_on_fewer_pairs_is_a_vain_wake(example_rig):
    """One pair short of :data:`ONE_VIEW_NOT_VAIN_PAIRS` in one view alone (a screen's pictures read as a person a
    pair or two in a row) leaves the wake to its round, which finds nobody: a vain wake for the cells it woke."""
    oracle, est = resting_estimator(example_rig, rest_every=8)
    seen = visit_seen_by_one_camera(est, oracle, example_rig, 3.0, ONE_VIEW_NOT_VAIN_PAIRS - 1)
    assert seen[1:] == [example_rig.pair[0].name] * (ONE_VIEW_NOT_VAIN_PAIRS - 1)
    assert est._vain_wakes is not None and all(counts.max() == 1 for counts in est._vain_wakes)


@pytest.mark.parametrize("step_s, vain", [(0.4, False), (0.6, True), (60.0, True)])
def test_one_view_pairs_further_apart_than_max_gap_are_no_run(example_rig, step_s, vain):
    """Session 72: the pairs of a run in one view alone must each come within ``tracking.max_gap_s`` (0.5 s) of the
    last, as a track's must: :data:`ONE_VIEW_NOT_VAIN_PAIRS` such pairs 0.6 s or a minute apart (dropped pairs, a
    stalled camera) are each a run of one, and the wake stays to its round, vain. Before, they counted in a row."""
    oracle, est = resting_estimator(example_rig, rest_every=8)
    assert est.config.tracking.max_gap_s == 0.5
    seen = visit_seen_by_one_camera(est, oracle, example_rig, 3.0, ONE_VIEW_NOT_VAIN_PAIRS, step_s)
    assert seen[1:] == [example_rig.pair[0].name] * ONE_VIEW_NOT_VAIN_PAIRS
    assert (est._vain_wakes is not None) == vain
    if vain:
        assert all(counts.max() == 1 for counts in est._vain_wakes)


def test_a_reset_leaves_no_wake_to_judge(example_rig, far_person):
    """A wake still to be judged (the walk-in seen by one camera alone so far) is forgotten by ``reset()`` with the
    restless cells: the round after it that finds nobody counts no vain wake against the cells that woke it."""
    images, joints = far_person
    oracle, est = resting_estimator(example_rig, rest_every=8)
    oracle.set_truth(joints, seen_by(np.ones((2, len(joints)), bool), 0))
    est.estimate(images)  # the walk-in wakes the rest
    assert est.estimate(images).single_view == example_rig.pair[0].name and est._woke_on is not None
    est.reset()
    oracle.set_truth(None)
    for room in far_scene_room(example_rig, [2.0 + i / 30.0 for i in range(5)]):  # a whole round finds nobody
        assert est.estimate(room).missing.all()
    assert est._tile_rest_wait > 0  # resting again
    assert est._vain_wakes is None


class FaintSmallPeopleOracle(SmallPeopleBlindOracle):
    """The blind oracle answering a person too small to find with their heatmaps at :data:`FAINT` of their height
    rather than none: peaks under the presence threshold where they stand, the weak evidence of a real model."""

    FAINT = 0.2

    def run(self, graph, feeds):
        out = OracleSession.run(self, graph, feeds)
        if graph in ("encoder", "human") and self.truth is not None and self._too_small(feeds["src_P"]):
            out["encoder_heatmaps"] = out["encoder_heatmaps"] * self.FAINT
        return out


def test_a_cold_pass_s_faint_peaks_pick_the_tile_searched_first(example_rig, far_person):
    """The whole volume's crop draws the person 4 m ahead faintly: the tile their peaks' rays meet in, the far left
    one, is searched on the first pair (in the fixed order the near left one came first, found nobody, and the far
    left one found them a pair later)."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    oracle.set_truth(joints)
    first = est.estimate(images)
    assert not first.missing.all()
    assert est.cold_tile_passes == 1 and est.cold_tiles_found == 1


def test_a_faint_peak_in_a_tile_already_searched_leaves_the_fixed_order(example_rig, far_person):
    """A tile this round searched in vain is not searched again on the same faint evidence: the round goes on in the
    fixed order, so that a peak that is no one cannot keep the other tiles unsearched."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    oracle.set_truth(joints)
    est.estimate(images)
    cold = est._pass(images, est.tracker.volume_regions, 0, {}, None)
    picked = est._tile_by_evidence(cold)
    assert picked is not None
    est._tiles_tried = frozenset({picked})
    assert est._tile_by_evidence(cold) is None


@pytest.mark.parametrize("lift_m, kept", [(0.6, False), (0.2, True)])
def test_a_tile_find_whose_feet_float_is_refused(example_rig, far_person, lift_m, kept):
    """A tile's find whose lower foot stands over 0.4 m above the floor (the person drawn lifted 0.6 m: as the model
    reads a person whom the frame's near edge cuts, whole and shrunk, too far and too high) is not kept: nobody on
    that pair, and the next pair starts cold; a foot 0.2 m up (a step) is kept."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    oracle.set_truth(joints - [0.0, lift_m, 0.0])
    first = est.estimate(images)
    assert first.missing.all() != kept
    assert est.cold_tile_passes == 1 and est.cold_tiles_found == int(kept)
    assert est.tile_finds_floating == int(not kept)
    assert (est.tracker.track is not None) == kept
    if kept:
        assert first.lowest_foot_m == pytest.approx(lift_m, abs=0.1)


@pytest.mark.parametrize("bound, kept", [(None, True), (0.8, True), (0.4, False), (0.2, False)])
def test_the_floating_foot_bound_is_the_config_s(example_rig, far_person, bound, kept):
    """``tracking.cold_tiles_max_foot_m`` (session 72; a module constant before, which the benchmark patched): the
    person drawn 0.6 m up is refused under a bound below that and kept under one above it, or under None."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig(tracking=TrackingConfig(cold_tiles_max_foot_m=bound)))
    oracle.set_truth(joints - [0.0, 0.6, 0.0])
    est.estimate(images)
    assert est.cold_tiles_found == int(kept) and est.tile_finds_floating == int(not kept)


@pytest.mark.parametrize("value", [-0.1, 10.5, float("nan"), float("inf"), "0.4", True])
def test_the_floating_foot_bound_out_of_range_is_an_error_naming_the_field_and_value(value):
    with pytest.raises(ConfigError, match="cold_tiles_max_foot_m") as e:
        TrackingConfig(cold_tiles_max_foot_m=value)
    assert repr(value) in str(e.value) or str(value) in str(e.value)


def test_a_refused_tile_find_leaves_no_novel_view_rendering(example_rig, far_person, monkeypatch):
    """The refused find's refined pass is tracked: with ``novel_view.overlap`` it started its novel view in the
    worker. The pair answers nobody, so that render is abandoned with the pass, not left running behind the pair
    (a stand-in job on the refined pass: whether it is abandoned is all the test reads)."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    abandoned = []

    class Job:
        def abandon(self):
            abandoned.append(self)

    refined = est._refined

    def rendering(images, p, *args):
        q = refined(images, p, *args)
        if q is not p:
            q.novel = Job()
        return q

    monkeypatch.setattr(est, "_refined", rendering)
    oracle.set_truth(joints - [0.0, 0.6, 0.0])
    assert est.estimate(images).missing.all() and est.tile_finds_floating == 1
    assert len(abandoned) == 1


def test_a_refused_tile_find_s_foot_is_the_find_s(example_rig, far_person):
    """``Estimator.tile_find_foot_m`` (``--tile-finds``' foot) is the find's: a refused find's pair answers nobody,
    whose ``PairResult.lowest_foot_m`` is None, and the table printed "-" where the estimator read the foot 0.6 m up.
    A pair that searches no tile has none (the next one, tracked, after a kept find)."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, example_rig, EstimatorConfig())
    oracle.set_truth(joints - [0.0, 0.6, 0.0])  # drawn 0.6 m up: refused (-k feet_float)
    r = est.estimate(images)
    assert est.tile_finds_floating == 1 and r.lowest_foot_m is None
    assert est.tile_find_foot_m == pytest.approx(0.6, abs=0.1)
    oracle.set_truth(joints)
    est.reset()
    est.estimate(images)
    assert est.cold_tiles_found == 1 and est.tile_find_foot_m == pytest.approx(0.0, abs=0.1)
    est.estimate(images)
    assert est.cold_tile_passes == 2 and est.tile_find_foot_m is None


@pytest.mark.parametrize("lift_m, up_m, kept", [(0.5, 0.0, True), (1.2, 0.0, True), (1.2, 0.6, False)])
def test_a_tile_find_on_a_rig_whose_frame_lies_under_the_floor_is_judged_on_its_volume_s_floor(
        example_rig, far_person, lift_m, up_m, kept):
    """The example rig with its frame's origin ``lift_m`` under the floor (``measure_baseline.lifted``: the floor at
    y = -lift_m, every foot read that much up): the refusal of floating feet reads the floor at the working volume's
    floor-side bound there (y = 0.05 - lift_m), so a person standing on the floor is kept (before session 71 every
    tile find was refused, the feet read 0.5 or 1.2 m up) and one drawn 0.6 m above it is still refused. At 0.5 m
    ``volume_floor_warning`` is silent (the volume's bound 0.45 m above y = 0)."""
    images, joints = far_person
    oracle = FaintSmallPeopleOracle(edge128_contract())
    est = Estimator(oracle, lifted(example_rig, lift_m), EstimatorConfig())
    oracle.set_truth(joints - [0.0, lift_m + up_m, 0.0])  # the rig's frame: the same pixels
    first = est.estimate(images)
    assert est.cold_tile_passes == 1 and est.tile_finds_floating == int(not kept)
    assert est.cold_tiles_found == int(kept) and first.missing.all() != kept
    assert est.tile_find_foot_m == pytest.approx(up_m + 0.05, abs=0.1)  # (the volume's bound 5 cm under the floor)
