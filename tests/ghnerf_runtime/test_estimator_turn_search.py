"""``roi.turn_search``: a cold pair that finds nobody, or someone weakly, tries each camera's crop turned.

The encoder learnt upright people only: through upright crops the shipped model finds nobody lying across the view
and reads an upside-down person as an upright one, feet where the head is (docs/turn-search.md, "Lying and upside
down, rendered"). Renders bench scenes with the body turned (``benchmarks/measure_lying_rendered.py``'s poses) and
runs the shipped model with the search off and on; upright people must not pay for it.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import EstimatorConfig, RoiConfig, SessionConfig
from ghnerf_runtime.errors import ConfigError

MODELS = Path(__file__).resolve().parents[2] / "models"
needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model in models/")
FPS = 30.0


def test_turn_search_keys_are_validated():
    # on by default since session 57 (off before; docs/turn-search.md, "On by default"): unset, on where the model has encoder heatmaps
    assert RoiConfig().turn_search is None
    assert RoiConfig().search_for(True).turn_search is True and RoiConfig().search_for(False).turn_search is False
    for value in (True, False):  # set: as set, whatever the model (true refuses one without: below)
        assert RoiConfig(turn_search=value).search_for(not value).turn_search is value
    with pytest.raises(ConfigError, match="turn_search"):
        RoiConfig(turn_search="yes")
    for bad in (-0.1, 1.5, float("nan"), None):
        with pytest.raises(ConfigError, match="turn_search_below"):
            RoiConfig(turn_search_below=bad)
    for bad in (0, 2.5, True, 1001):
        with pytest.raises(ConfigError, match="turn_search_every"):
            RoiConfig(turn_search_every=bad)


def test_view_score_is_the_median_joint_peak_per_view():
    from ghnerf_runtime.estimator import _view_score

    heat = np.zeros((2, 5, 4, 4), np.float32)
    heat[0, :, 1, 2] = [0.9, 0.2, 0.5, 1.7, 0.1]  # a peak above 1 counts 1; median 0.5
    heat[1, :, 0, 0] = [0.3, 0.8, 0.8, 0.8, 0.8]
    heat[1, 0, 3, 3] = np.nan  # a map with a non-finite value has no peak (the decoder drops that joint)
    np.testing.assert_allclose(_view_score(heat), [0.5, 0.8])
    heat[1, 3:, 3, 3] = np.inf  # not a full-strength peak either
    np.testing.assert_allclose(_view_score(heat), [0.5, 0.0])


class _Scored:
    """Stands in for the estimator in :meth:`Estimator._turn_candidates`: given view scores per turn."""

    def __init__(self, scores: dict[int, list[float]]) -> None:
        self.scores = scores

    def _turn_scores(self, images, turn, timing, track=None):
        return np.array(self.scores[turn])


@pytest.mark.parametrize("scores, expected", [
    # cameras facing each other: the body rolled one way in one view, the other way in the other (then the common
    # turn of the best summed score)
    ({90: [0.6, 0.1], 180: [0.2, 0.2], 270: [0.1, 0.7]}, [(90, 270), (270, 270)]),
    # one view clearly better turned, the other only a little: its own turn first, then the common one
    ({90: [0.1, 0.1], 180: [0.7, 0.34], 270: [0.1, 0.1]}, [(180, 0), (180, 180)]),
    # both alike: one candidate
    ({90: [0.1, 0.1], 180: [0.6, 0.6], 270: [0.1, 0.1]}, [(180, 180)]),
    # no turn clearly better than upright: nothing to try
    ({90: [0.35, 0.3], 180: [0.3, 0.35], 270: [0.1, 0.1]}, []),
])
def test_turn_candidates_are_per_view_then_common(scores, expected):
    from ghnerf_runtime.estimator import Estimator

    base = np.array([0.3, 0.3])  # the upright crops' view scores
    assert Estimator._turn_candidates(_Scored(scores), None, base, {}) == expected


@pytest.fixture(scope="module")
def session():
    from ghnerf_runtime.estimator import load_session

    return load_session(EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf"), warmup=False)))


def _shots(k: int, pose: str, frames: int = 3):
    """``frames`` consecutive pairs at 30 fps of bench scene ``k`` with the body in ``pose``: (rig, [(t, images,
    true 3D joints)])."""
    from benchmarks.measure_lying_rendered import posed_as, render_pair
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene

    rig, scene, t0, _ = bench_rig_and_scene(k)
    out = []
    for i in range(frames):
        posed = posed_as(scene.posed(t0 + i / FPS), pose, rig.volume)
        images, _, _ = render_pair(scene, rig, posed, t0 + i / FPS)
        out.append((i / FPS, images, posed.joints.copy()))
    return rig, out


def _run(session, rig, shots, search: bool, every: int = 5):
    """Each pair's (result, 3D error of the found joints in mm, the search count after it) and the estimator."""
    from ghnerf_runtime.estimator import Estimator

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                          roi=RoiConfig(turn_search=search, turn_search_every=every))
    est = Estimator(session, rig, cfg)
    out = []
    for t, images, truth in shots:
        r = est.estimate(images, timestamp_s=t)
        ok = ~r.missing
        err = 1e3 * np.linalg.norm(r.joints_3d[ok] - truth[ok], axis=1)
        out.append((r, float(np.mean(err)) if ok.any() else np.inf, est.turn_searches))
    return out, est


@needs_model
@pytest.mark.parametrize("pose, turn", [("lying_z", 90), ("upside_down", 180)])
def test_the_search_finds_a_person_lying_or_upside_down_and_keeps_the_turn(session, pose, turn):
    rig, shots = _shots(1, pose)
    off, _ = _run(session, rig, shots, search=False)
    on, est = _run(session, rig, shots, search=True)
    # upright crops: nobody, or a skeleton the wrong way up (a metre off)
    assert all(r.missing.sum() > 20 or err > 500 for r, err, _ in off), [(int((~r.missing).sum()), e) for r, e, _ in off]
    for r, err, _ in on:
        assert (~r.missing).sum() >= 20 and err < 150, (pose, int((~r.missing).sum()), err)
    assert est._turns == (turn, turn)
    # searched on the cold pair only: the next pairs come tracked, with the turned crops
    assert [n for _, _, n in on] == [1, 1, 1] and est.turns_kept == 1
    assert [r.tracked for r, _, _ in on] == [True, True, True]


@needs_model
def test_the_defaults_right_an_upside_down_person(session):
    """The search is on by default (session 57): an estimator built with the default config reads an upside-down
    person through crops turned 180 degrees, where upright crops read them standing, a metre off."""
    from ghnerf_runtime.estimator import Estimator

    rig, shots = _shots(1, "upside_down")
    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf"))))
    assert est.config.roi.turn_search is True
    for t, images, truth in shots:
        r = est.estimate(images, timestamp_s=t)
        ok = ~r.missing
        err = 1e3 * float(np.mean(np.linalg.norm(r.joints_3d[ok] - truth[ok], axis=1))) if ok.any() else np.inf
        assert ok.sum() >= 20 and err < 150, (int(ok.sum()), err)
    assert est._turns == (180, 180) and est.turn_searches == 1 and est.turns_kept == 1


@needs_model
def test_upright_people_do_not_search_and_get_the_same_joints(session):
    for k in (0, 1, 2):
        rig, shots = _shots(k, "upright")
        off, _ = _run(session, rig, shots, search=False)
        on, est = _run(session, rig, shots, search=True)
        assert est.turn_searches == 0 and est._turns == (0, 0)
        for (a, _, _), (b, _, _) in zip(off, on):
            np.testing.assert_array_equal(a.missing, b.missing)
            np.testing.assert_array_equal(a.joints_3d, b.joints_3d)


@needs_model
def test_a_lost_turned_track_looks_upright_first(session):
    """Once the turned track is lost (here: forgotten), the next cold pass is upright, and an upright person
    there is found without a search."""
    rig, lying = _shots(1, "lying_z", frames=1)
    _, upright = _shots(1, "upright", frames=1)
    on, est = _run(session, rig, lying, search=True)
    assert est._turns == (90, 90)
    est.reset()
    r = est.estimate(upright[0][1], timestamp_s=1.0)
    assert est._turns == (0, 0) and est.turn_searches == 1 and (~r.missing).sum() >= 20


@needs_model
def test_one_person_lying_flagged_as_two_with_pick_subject_none_is_still_searched_for(session):
    """Session 57's review: with ``pick_subject: none`` a flagged pair that reported nobody no longer searches when
    both views read bodies strongly (two people upright: no turn helps, nobody is picked). The upright crops of one
    person lying across the view in bench scene 11 show 6 joints twice, flagged as two people (each view's median
    joint peak 0.26-0.30): that pair still searches, and the turned crops find them."""
    from ghnerf_runtime.config import Joints3DConfig
    from ghnerf_runtime.estimator import Estimator

    rig, shots = _shots(11, "lying_z", frames=1)
    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                  joints3d=Joints3DConfig(pick_subject="none")))
    flagged = []
    upright = est._finish_pass

    def spy(*args, **kwargs):
        p = upright(*args, **kwargs)
        flagged.append((est._turns, p.several_people))
        return p

    est._finish_pass = spy
    r = est.estimate(shots[0][1], timestamp_s=0.0)
    assert flagged[0] == ((0, 0), True)  # (the upright cold pass: one person read as two)
    assert not r.several_people and r.num_found >= 20 and est._turns == (90, 90) and est.turns_kept == 1


@needs_model
def test_a_person_no_turn_rights_is_searched_for_every_few_pairs(session):
    """Lying along the line of sight no turn shows an upright person: after a search that kept nothing, only
    every ``turn_search_every``-th weak cold pair searches again."""
    rig, shots = _shots(1, "lying_x", frames=7)
    every, _ = _run(session, rig, shots, search=True, every=1)
    assert [n for _, _, n in every] == [1, 2, 3, 4, 5, 6, 7]
    fifth, est = _run(session, rig, shots, search=True, every=5)
    assert [n for _, _, n in fifth] == [1, 1, 1, 1, 1, 2, 2] and est.turns_kept == 0
    assert all(r.missing.all() for r, _, _ in every + fifth)  # nobody found either way: the searches cost only


@needs_model
def test_the_turns_share_each_cameras_remap_table_cache(session):
    """``roi.map_cache_size`` bounds the remap tables kept per camera whatever the crop turns: each turn kept its
    own cache of that size, so a device searching the turns could hold four times the tables (each 2S x 2S at
    ``roi.supersample`` 2; docs/daemon.md measured the upright caches' fill at about 50 MB)."""
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.preprocess import Roi

    rig, _, _, _ = bench_rig_and_scene(0)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                          roi=RoiConfig(turn_search=True, map_cache_size=3))
    est = Estimator(session, rig, cfg)
    rois = [Roi(8 * k, 8 * k, 128) for k in range(4)]
    crops = {}
    for turns in ((0, 0), (90, 90), (180, 270), (270, 90)):
        est._use_turns(turns)
        for roi in rois:
            for i, st in enumerate(est._cams):
                crops[i, turns[i], roi] = est._crop(st, roi)[1]
    for i in (0, 1):
        tables = {id(entry) for (cam, _), st in est._turned_cams.items() if cam == i for entry in st.cache.values()}
        assert len(tables) <= 3, (i, len(tables))
    # a turn's tables are its own: the same window turned another way is another crop (its camera rolled)
    est._use_turns((0, 90))
    upright, turned = (est._crop(st, rois[0])[1] for st in est._cams)
    np.testing.assert_allclose(upright.K, crops[0, 0, rois[0]].K)
    np.testing.assert_allclose(turned.R, crops[1, 90, rois[0]].R)
    assert not np.allclose(turned.R, crops[1, 0, rois[0]].R)


@pytest.mark.skipif(not (MODELS / "baseline").is_dir(), reason="no baseline model in models/")
def test_a_model_without_encoder_heatmaps_is_refused_at_load():
    """The search scores the turns by the encoder heatmaps: with the baseline (which has none) each weak cold
    pair raised KeyError('encoder_heatmaps') mid-stream; now the estimator (and so the daemon's config check)
    says so when built."""
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.config import HeatmapsConfig
    from ghnerf_runtime.errors import ModelError
    from ghnerf_runtime.estimator import Estimator, load_session

    rig, _, _, _ = bench_rig_and_scene(0)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "baseline"), warmup=False),
                          heatmaps=HeatmapsConfig(source="rendered"))
    baseline = load_session(cfg)
    Estimator(baseline, rig, replace(cfg, roi=RoiConfig(turn_search=False))).close()  # the search off: it serves
    # unset (the default, on since session 57) it is off for a model that cannot score the turns: it serves too
    with Estimator(baseline, rig, cfg) as est:
        assert est.config.roi.turn_search is False
    with pytest.raises(ModelError, match=r"roi\.turn_search .*encoder_heatmaps.* roi\.turn_search = false"):
        Estimator(baseline, rig, replace(cfg, roi=RoiConfig(turn_search=True)))


@needs_model
def test_a_weak_cold_pass_through_a_kept_turn_looks_upright_first(session):
    """A kept turn stays with a single-view track too (one camera's frame failed the check): the next pair's cold
    pass crops turned. When that pass is weak (the person got up) the search took the turned crops for the upright
    ones, never tried upright, and kept the upside-down crops of a standing person: 1.2 m off, then tracked so.
    Now such a pass is run again upright first, as after a lost track."""
    rig, lying = _shots(1, "lying_z", frames=2)
    _, upright = _shots(1, "upright", frames=4)
    t, images, _ = lying[1]
    blinded = (t, [images[0], np.zeros_like(images[1])], None)  # one camera's frame rejected (flat)
    pairs = [lying[0], blinded, upright[2], upright[3]]
    from ghnerf_runtime.estimator import Estimator

    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                  roi=RoiConfig(turn_search=True)))
    for k, (t, images, truth) in enumerate(pairs):
        r = est.estimate(images, timestamp_s=t)
        if k == 1:
            assert r.single_view is not None and est._turns == (90, 90)  # the view track keeps the turn
        if k >= 2:
            ok = ~r.missing
            err = 1e3 * float(np.mean(np.linalg.norm(r.joints_3d[ok] - truth[ok], axis=1)))
            assert est._turns == (0, 0) and ok.sum() >= 20 and err < 150, (k, est._turns, int(ok.sum()), err)


@needs_model
@pytest.mark.parametrize("degrees", [30, 90])
def test_the_turns_compose_with_a_rolled_cameras_upright_crops(session, degrees):
    """A turn is on top of ``roi.upright``'s roll: a rig mounted rolled finds an upside-down person with the same
    half turn as the upright rig (integration review: found so in a one-off look at 0/30/90/180 degrees)."""
    from benchmarks.measure_lying_rendered import posed_as, render_pair
    from benchmarks.measure_mounting import rolled
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.estimator import Estimator

    base, scene, t0, _ = bench_rig_and_scene(1)
    rig = rolled(base, degrees)
    posed = posed_as(scene.posed(t0), "upside_down", base.volume)
    images, _, _ = render_pair(scene, rig, posed, t0)
    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                  roi=RoiConfig(turn_search=True)))
    r = est.estimate(images, timestamp_s=0.0)
    ok = ~r.missing
    err = 1e3 * float(np.mean(np.linalg.norm(r.joints_3d[ok] - posed.joints[ok], axis=1)))
    np.testing.assert_allclose([st.roll_deg for st in est._cams], -degrees, atol=1e-6)
    assert est._turns == (180, 180) and ok.sum() >= 20 and err < 150, (est._turns, int(ok.sum()), err)


@needs_model
@pytest.mark.parametrize("fill", ["black", "edge", "fade"])
def test_the_estimator_crops_with_roi_pad_fill(session, fill):
    """``roi.pad_fill`` reaches the estimator's remap tables: past the frame's edge its crop shows zeros, the
    frame's edge, or that edge fading into the crop's mean over ``roi.pad_fade`` (docs/runtime.md, "A person at
    the frame's edge")."""
    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.preprocess import Roi, apply_crop_maps

    rig = bench_rig_and_scene(0)[0]
    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                  roi=RoiConfig(pad_fill=fill)))
    try:
        state = est._cams[0]
        maps, _ = est._crop(state, Roi(-200, 100, 300))
        frame = np.full((state.camera.height, state.camera.width, 3), 120, np.uint8)
        crop = apply_crop_maps(frame, maps)
        assert maps.inside is not None and not maps.inside.all()
        past = crop[~maps.inside]
        if fill == "edge":
            assert np.all(past == 120)
        elif fill == "fade":  # a uniform frame: its edge and its mean are the same colour
            assert maps.fade is not None and np.all(past == 120)
            frame[:, :4] = 250  # a bright left edge: repeated beside the frame, faded into the mean further out
            crop = apply_crop_maps(frame, maps)
            side = maps.inside.shape[0]
            band = crop[side // 4: -side // 4, : int(np.flatnonzero(~maps.inside[side // 2]).max()) + 1, 0]
            assert np.all(band[:, -1] > 200) and np.all(band[:, 0] < 160) and np.all(np.diff(band.astype(int)) >= -1)
        else:  # (but for bilinear taps into the frame along its edge)
            assert np.mean(past == 0) > 0.8
    finally:
        est.close()


@needs_model
@pytest.mark.parametrize("padding, configured, expected", [
    ("black", None, "black"),  # trained on black bands (TrainConfig.frame_padding): black crops by default
    ("none", None, "fade"),  # the shipped model's contract (its files have no ghnerf.frame_padding)
    ("black", "fade", "fade"),  # a fill the config sets wins, said once at load
    ("none", "black", "black"),
])
def test_an_unset_pad_fill_pads_the_crops_as_the_model_was_trained(session, caplog, padding, configured, expected):
    """``roi.pad_fill`` unset: the estimator's crops show what the model's training crops showed past the frame
    (its contract's ``frame_padding``), zeros for a model trained on black bands, fade for the shipped model; a
    fill in the config wins, and the load logs it when it is not the model's (docs/runtime.md, "A person at the
    frame's edge")."""
    import logging

    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.preprocess import Roi, apply_crop_maps

    shipped = session.contract
    assert shipped.frame_padding == "none"
    rig = bench_rig_and_scene(0)[0]
    session.contract = replace(shipped, frame_padding=padding)  # the same graphs, trained as said
    try:
        with caplog.at_level(logging.INFO, logger="ghnerf_runtime.estimator"):
            est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                          roi=RoiConfig(pad_fill=configured)))
    finally:
        session.contract = shipped
    try:
        assert est.config.roi.pad_fill == expected
        state = est._cams[0]
        maps, _ = est._crop(state, Roi(-200, 100, 300))
        crop = apply_crop_maps(np.full((state.camera.height, state.camera.width, 3), 120, np.uint8), maps)
        past = crop[~maps.inside]
        if expected == "black":  # (but for bilinear taps into the frame along its edge)
            assert np.mean(past == 0) > 0.8
        else:  # a uniform frame: its faded edge is its colour
            assert maps.fade is not None and np.all(past == 120)
        said = [r.getMessage() for r in caplog.records if "roi.pad_fill" in r.getMessage()]
        differs = configured is not None and configured != RoiConfig.model_fill(padding)
        assert len(said) == differs and all(repr(padding) in m and repr(configured) in m for m in said), said
    finally:
        est.close()


def _changing(session, k: int, before: str, after: str, n_before: int, n_after: int):
    """Bench scene ``k`` at 30 fps, the body in pose ``before`` for ``n_before`` pairs, then in ``after``, run
    with the search on: per pair (the crops' turns after it, tracked, joints found, 3D error in mm) and the
    estimator."""
    from benchmarks.measure_lying_rendered import posed_as, render_pair
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene
    from ghnerf_runtime.estimator import Estimator

    rig, scene, t0, _ = bench_rig_and_scene(k)
    est = Estimator(session, rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                                                  roi=RoiConfig(turn_search=True)))
    out = []
    for i in range(n_before + n_after):
        posed = posed_as(scene.posed(t0 + i / FPS), before if i < n_before else after, rig.volume)
        images, _, _ = render_pair(scene, rig, posed, t0 + i / FPS)
        r = est.estimate(images, timestamp_s=i / FPS)
        ok = ~r.missing
        err = 1e3 * float(np.mean(np.linalg.norm(r.joints_3d[ok] - posed.joints[ok], axis=1))) if ok.any() else np.inf
        out.append((est._turns, r.tracked, int(ok.sum()), round(err) if ok.any() else err))  # inf: nobody
    return out, est


@needs_model
@pytest.mark.parametrize("k", [1, 2])
def test_a_tracked_person_who_gets_up_leaves_the_turn(session, k):
    """Upside down for two pairs (found by the search, then tracked through half-turned crops), then standing: the
    track held, and a tracked pair never searched, so the turned crops read the standing person upside down, 1.1-1.3
    m off, at median confidences of 0.44-0.57, for all four pairs (the code before, in these scenes). Now a weak
    tracked turned pass (or every ``turn_search_every``-th) is run again through upright crops of its track, and the
    turn is left when upright finds the person more confidently."""
    out, est = _changing(session, k, "upside_down", "upright", 2, 4)
    assert all(turns == (180, 180) and err < 150 for turns, _, _, err in out[:2]), out
    # within two pairs of getting up (one here), read upright, and tracked throughout
    for turns, tracked, found, err in out[3:]:
        assert turns == (0, 0) and tracked and found >= 20 and err < 150, out
    assert est.turns_left == 1 and est.turn_checks >= 1 and est.turn_searches == 1


@needs_model
@pytest.mark.parametrize("k", [2, 3])
def test_a_tracked_person_upside_down_is_searched_for_on_the_track(session, k):
    """Standing for two pairs (tracked upright), then upside down: the upright tracked crops read a standing person,
    0.7-1.4 m off at 0.31-0.43 median confidence, whom the track kept, for all four pairs (the code before, in
    these scenes). Now a weak tracked upright pass searches the turns on its track's crops."""
    out, est = _changing(session, k, "upright", "upside_down", 2, 4)
    assert all(turns == (0, 0) and err < 60 for turns, _, _, err in out[:2]), out
    for turns, tracked, found, err in out[2:]:
        assert turns == (180, 180) and tracked and found >= 20 and err < 150, out
    assert est.turn_searches == 1 and est.turns_kept == 1


@needs_model
def test_a_strong_turned_track_is_checked_upright_every_few_pairs_and_keeps_its_turn(session):
    """A tracked turned pass that is not weak is still checked upright every ``turn_search_every``-th tracked pair
    (a misread over ``turn_search_below``); a person still lying keeps the turn through the checks."""
    from ghnerf_runtime.estimator import Estimator

    rig, shots = _shots(1, "lying_z", frames=7)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf")),
                          roi=RoiConfig(turn_search=True, turn_search_every=2, turn_search_below=0.0))
    est = Estimator(session, rig, cfg)
    checks = []
    for t, images, truth in shots:
        r = est.estimate(images, timestamp_s=t)
        checks.append(est.turn_checks)
        assert est._turns == (90, 90) and r.tracked and (~r.missing).sum() >= 18, (est._turns, checks)
    # the search compared the turn with upright on the cold pair: the first check two tracked pairs later
    assert checks == [0, 0, 1, 1, 2, 2, 3] and est.turns_left == 0 and est.turn_searches == 1


def _tracked_through(turns: tuple[int, int]):
    """An estimator on the oracle session (no model, the turn search on) tracking one scene's person through crops
    turned ``turns``: (estimator, rig, that person's joints)."""
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator

    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    est = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(roi=RoiConfig(turn_search=True)))
    joints = sim.SimScene(sim.SceneConfig(seed=1)).joints_3d(0.0)
    est._use_turns(turns)
    assert est.tracker.update(joints, np.ones(len(joints), np.float32), np.ones(len(joints), bool), 0)
    return est, rig, joints


def _held_track_estimator(turns: tuple[int, int]):
    """An estimator on the oracle session (no model) crops turned ``turns``, with a track of one scene's person;
    ``_pass`` is replaced by a spy that records the hold it is asked with (``_several_track``, ``_behind_track``,
    the crops' turns) and, as an unflagged pass's ``_finish_pass`` would, clears the hold and finds nobody."""
    from ghnerf_runtime.estimator import _Pass
    from ghnerf_runtime.joints3d import Joints3D

    est, _, joints = _tracked_through(turns)
    asked = []
    frame_ok = {n: None for n in est.camera_names}

    def spy(images, regions, sequence, timing, novel_view=None, cold_several=None):
        asked.append((est._several_track, est._behind_track, est._turns))
        est._several_track, est._behind_track = False, None
        return _Pass(regions, frame_ok, j3=Joints3D.missing(len(joints)), someone=False)

    est._pass = spy
    weak = _Pass(est.tracker.regions(), frame_ok, env={"encoder_heatmaps": np.zeros((2, len(joints), 4, 4))},
                 j3=Joints3D.missing(len(joints)), someone=False)
    return est, weak, asked


@pytest.mark.parametrize("held", [(True, None), (True, 1)])
def test_a_turn_check_reruns_a_flagged_track_upright_with_its_hold_and_keeps_it(held):
    """Integration review (session 56): a tracked pass through a kept turn whose track follows a ``several_people``
    pass (flagged in both views, or by one view alone: ``SubjectSelector.behind_view``) is checked upright on that
    track. The upright rerun was asked with the hold dropped (``_use_turns`` resets it for a new track), so its subject's crop,
    showing fewer of the other person's joints twice, went unflagged and let their peaks into the joints (kept when
    more confident); and where the turn stood, the one-view hold's view was lost (``_several_track`` restored,
    ``_behind_track`` left as the rerun's). Now the rerun follows the track with its hold, and the hold stands."""
    est, weak, asked = _held_track_estimator((180, 180))
    est._several_track, est._behind_track = held
    assert est._turn_check([None, None], weak, 0, {}, None) is weak
    assert asked == [(*held, (0, 0))]
    assert (est._several_track, est._behind_track, est._turns) == (*held, (180, 180))


@pytest.mark.parametrize("held", [(True, None), (True, 0)])
def test_a_tracked_turn_search_follows_a_flagged_track_with_its_hold_and_keeps_it(held):
    """As the turn check: a weak tracked upright pass of a flagged track searches the turns on that track, each
    turned pass asked with the track's hold; upright (no turn kept) stands with it."""
    est, weak, asked = _held_track_estimator((0, 0))
    est._turn_candidates = lambda images, base, timing, track=None: [(180, 180)]
    est._several_track, est._behind_track = held
    assert est._turn_search([None, None], weak, 0, {}, None, est.tracker.track) is weak
    assert asked == [(*held, (180, 180))]
    assert (est._several_track, est._behind_track, est._turns) == (*held, (0, 0))


def test_reset_returns_to_upright_crops_with_the_turn_state_cleared():
    """Integration review (session 57): ``reset()`` forgot the kept turn's track but left the crops turned and the
    turn check's count (harmless: the next pair, cold, went upright); a fresh start is upright crops with both
    cleared, every tracker forgotten. The search's counters are statistics over the estimator's life and stay."""
    est, _, _ = _held_track_estimator((180, 90))
    est._turn_check_wait, est.turn_searches, est.turns_kept, est.turn_checks = 3, 2, 1, 4
    est._kept_axis = np.array([1.0, 0.0, 0.0])  # the last pass kept through the turn lay across the view
    est._failed_search_found = True  # a search that kept no turn, over a pass that found someone
    est._failed_search_short = 5.0  # and that refused a body 5 degrees short of lying
    turned = est.tracker
    est.reset()
    assert est._turns == (0, 0) and [st.turn_deg for st in est._cams] == [0.0, 0.0]
    assert est.tracker is est._turned_trackers[0, 0] and est.tracker.track is None and turned.track is None
    assert est._turn_check_wait == 0 and est._turn_search_wait == 0 and est._kept_axis is None
    assert not est._failed_search_found and est._failed_search_short is None
    assert (est.turn_searches, est.turns_kept, est.turn_checks) == (2, 1, 4)


def _turned_body(axis: int, degrees: float, at=(0.0, 0.0, 3.0)):
    """A standing person's joints (drivers.sim, rig frame, y down) turned ``degrees`` about rig axis ``axis`` through
    their centroid, moved there: a body 3 m ahead of cameras at the rig's origin."""
    from benchmarks.measure_lying_rendered import rotation
    from ghnerf_runtime.joints3d import Joints3D

    sim = pytest.importorskip("drivers.sim")
    joints = sim.SimScene(sim.SceneConfig(seed=1)).joints_3d(0.0)
    centre = joints.mean(axis=0)
    points = (joints - centre) @ rotation(axis, degrees).T + np.asarray(at)
    n = len(points)
    return Joints3D(points, np.ones(n, np.float32), np.ones(n, bool), np.zeros((n, 2), np.float32))


CAMERA_CENTRES = [np.array([-0.1, -1.2, 0.0]), np.array([0.1, -1.2, 0.0])]  # a pair 1.2 m up, looking along +z


@pytest.mark.parametrize("axis, degrees, lies", [
    (2, 90.0, True),  # lying across the view (a quarter turn rights it)
    (2, -90.0, True),
    (2, 180.0, True),  # upside down (a half turn)
    (2, 170.0, True),  # a handstand leaning 10 degrees
    (0, 90.0, False),  # lying along the line of sight: level, but no view shows its length
    (0, -90.0, False),
    (0, 135.0, False),  # head down, tilted halfway: the encoder's upright person across the picture (lying_x)
    (2, 125.0, False),
    (2, 0.0, False),  # standing: no turn was needed to read it
])
def test_a_turned_pass_is_taken_only_lying_or_upside_down_across_the_views(axis, degrees, lies):
    """``lies_as_turned``: what a turned pass's body must look like to be kept. Lying along the line of sight (no turn
    rights it) the old search kept a half-turned pass's skeleton level along the line of sight, or one tilted off
    the floor toward the cameras (0.25-1.2 m off: docs/turn-search.md, "Searching the crop turns")."""
    from ghnerf_runtime.body_lie import lies_as_turned

    assert lies_as_turned(_turned_body(axis, degrees), CAMERA_CENTRES) is lies


def test_a_turned_pass_that_does_not_show_how_the_body_lies_is_not_taken():
    """No head and shoulders, or no hips and legs found: no body axis, so nothing says the turn righted anyone."""
    from dataclasses import replace as dc_replace

    from ghnerf_runtime.body25 import JOINT_INDEX
    from ghnerf_runtime.body_lie import body_axis, lies_as_turned

    j3 = _turned_body(2, 180.0)
    np.testing.assert_allclose(body_axis(j3), [0.0, 1.0, 0.0], atol=0.1)  # upside down: the head below (y down)
    for group in (("Nose", "Neck", "RShoulder", "LShoulder", "REye", "LEye", "REar", "LEar"),
                  ("MidHip", "RHip", "LHip", "RKnee", "LKnee", "RAnkle", "LAnkle")):
        valid = j3.valid.copy()
        valid[[JOINT_INDEX[n] for n in group]] = False
        headless = dc_replace(j3, valid=valid)
        assert body_axis(headless) is None and not lies_as_turned(headless, CAMERA_CENTRES)


@needs_model
@pytest.mark.parametrize("k, frames", [(17, 1), (0, 6)])
def test_a_turned_pass_of_someone_lying_along_the_line_of_sight_is_refused(session, k, frames):
    """Lying along the line of sight no turn rights the body, but a half-turned pass found someone more confidently
    than upright and was kept: in scene 17 at its first pair, a skeleton level along the line of sight 0.25 m off;
    in scene 0 at pair 5, one standing tilted head down off the floor, 0.63 m off, then tracked (the code before).
    Now such a pass is refused (``lies_as_turned``) and upright, which found nobody, stands, as with the search
    off."""
    rig, shots = _shots(k, "lying_x", frames=frames)
    off, _ = _run(session, rig, shots, search=False)
    on, est = _run(session, rig, shots, search=True)
    assert est.turns_kept == 0 and est._turns == (0, 0), (est.turns_kept, est._turns)
    for (a, _, _), (b, _, _) in zip(off, on):  # what the search off reports
        np.testing.assert_array_equal(a.missing, b.missing)
        np.testing.assert_array_equal(a.joints_3d, b.joints_3d)
    assert est.turns_refused >= 1 and est.turn_searches >= 1


@needs_model
def test_a_tracked_person_who_rolls_onto_the_line_of_sight_is_not_kept_turned(session):
    """Lying across the view for three pairs (found by the search, tracked through quarter-turned crops), then lying
    along the line of sight: the tracked turned pass read the encoder's upright person across the picture, 16 joints
    0.65 m off, and held it (the code before, bench scene 21: the rule of ``lies_as_turned`` was asked of a search's
    passes only). Now a kept turn's pass whose body lies as no turn rights is refused too, and the pair is read as
    after a lost track, upright first: nobody, as with the search off."""
    out, est = _changing(session, 21, "lying_z", "lying_x", 3, 2)
    assert all(turns == (90, 90) and found >= 20 and err < 150 for turns, _, found, err in out[:3]), out
    for turns, _, found, err in out[3:]:
        assert turns == (0, 0) and (found == 0 or err < 150), out
    assert est.turns_refused >= 1 and est.turns_kept == 1, (est.turns_refused, est.turns_kept)


def _lying_along_sight(est, joints: np.ndarray):
    """``joints`` (a standing person's, rig frame) turned about their centroid so that their body axis runs along
    the estimator's first camera's line of sight to them: a body no crop turn rights."""
    from ghnerf_runtime.body_lie import body_axis
    from ghnerf_runtime.joints3d import Joints3D

    n = len(joints)
    standing = Joints3D(joints, np.ones(n, np.float32), np.ones(n, bool), np.zeros((n, 2), np.float32))
    centre = joints.mean(axis=0)
    a = body_axis(standing)
    d = centre - est._cams[0].camera.center
    d = d / np.linalg.norm(d)
    v, c = np.cross(a, d), float(a @ d)  # the rotation taking a onto d (Rodrigues; a is nowhere near -d here)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    R = np.eye(3) + vx + vx @ vx / (1.0 + c)
    return replace(standing, points=(joints - centre) @ R.T + centre)


@pytest.mark.parametrize("single_view_track", [False, True])
def test_a_kept_turns_pass_of_a_body_no_turn_rights_is_read_cold_upright(single_view_track):
    """A pass through a kept turn (quarter-turned crops) that is strong but whose body lies along a view's line of
    sight: before, it was kept with its skeleton and track: a tracked one (``_turn_check`` compared only confidences,
    and a strong pass between checks was not even compared), and the cold one of a single-view track (which keeps
    the turn; only a weak one went upright). Now it is refused (``turns_refused``) and the pair read as after a lost
    track: a cold pass through upright crops, whose answer (nobody, here) is reported."""
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.body_lie import lies_as_turned
    from ghnerf_runtime.estimator import Estimator, _Pass

    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    est = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(roi=RoiConfig(turn_search=True)))
    joints = sim.SimScene(sim.SceneConfig(seed=1)).joints_3d(0.0)
    est._use_turns((90, 90))
    assert est.tracker.update(joints, np.ones(len(joints), np.float32), np.ones(len(joints), bool), 0)
    est._turn_check_wait = 3  # a strong pass between checks: the code before did not look at it at all
    if single_view_track:  # one camera's frame was rejected last pair: the turned tracker holds that view's crop
        est.tracker.reset()
        est.tracker.view_track = (1, est.tracker.regions().rois[1])
    along = _lying_along_sight(est, joints)
    assert not lies_as_turned(along, [st.camera.center for st in est._cams])
    names = est.camera_names
    J = len(joints)
    frame_reason = {n: None for n in names}
    asked = []

    def spy(images, regions, sequence, timing, novel_view=None, cold_several=None):
        asked.append((est._turns, regions.tracked))
        if est._turns == (90, 90):  # the turned crops: the misread body, found confidently
            return _Pass(regions, frame_reason, j3=along, someone=True,
                         joints_2d={n: np.zeros((J, 2)) for n in names},
                         conf_2d={n: np.ones(J, np.float32) for n in names},
                         missing_2d={n: np.zeros(J, bool) for n in names})
        return _Pass(regions, frame_reason)  # upright, from the working volume: nobody (no joints)

    est._pass = spy
    images = [np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair]
    r = est.estimate(images)
    assert asked == [((90, 90), not single_view_track), ((0, 0), False)], asked
    assert r.missing.all() and not r.tracked
    assert est._turns == (0, 0) and est.turns_refused == 1 and est.tracker.track is None


@pytest.mark.parametrize("turns, axis, degrees, kept", [
    ((90, 90), 2, 90.0, True),  # lying across: what the quarter turn was kept for
    ((90, 90), 2, 60.0, True),  # rolling up on an elbow: still nearer the quarter turn than upright
    ((90, 90), 2, 125.0, True),  # rolling on over (a cartwheel): nearer the quarter turn than the half
    ((270, 270), 2, -55.0, True),  # the other way round
    ((90, 90), 2, 30.0, False),  # nearly up: upright crops show it better
    ((90, 90), 2, 150.0, False),  # nearer upside down: the half turn's body, not the quarter's
    ((180, 180), 2, 145.0, True),  # a handstand leaning 35 degrees
    ((180, 180), 2, 115.0, False),  # nearer level: the quarter turn's
    ((90, 90), 0, 90.0, False),  # lying along the line of sight: no turn rights it, kept or not
    ((90, 270), 2, 60.0, True),  # per-view turns (cameras facing each other see the roll opposite ways)
])
def test_a_kept_turn_holds_while_the_body_rolls_on_nearer_it_than_upright_or_the_next_turn(turns, axis, degrees,
                                                                                            kept):
    """``lies_as_kept_turn``: a kept turn's passes that roll on from the last one (its axis a few degrees away) are
    asked whether the body lies within 45 degrees of the turn (and across the views), not within the search's
    20-degree windows: a person rolling up from lying, or on over into a cartwheel, passes a few degrees a pair
    through tilts those windows refuse (docs/turn-search.md, "Gradual rolls"). The same body jumped to from lying
    across the view (a rigid roll: the encoder's misread), or with no pass before, is asked the search's rule."""
    from ghnerf_runtime.body_lie import body_axis, lies_as_kept_turn, lies_as_turned

    body = _turned_body(axis, degrees)
    step = -5.0 if degrees > 0 else 5.0  # the pass before: 5 degrees less rolled
    before = body_axis(_turned_body(axis, degrees + step))
    assert lies_as_kept_turn(body, CAMERA_CENTRES, turns, before) is kept
    strict = lies_as_turned(body, CAMERA_CENTRES)
    assert lies_as_kept_turn(body, CAMERA_CENTRES, turns, None) is strict
    if abs(abs(degrees) - 90.0) >= 30.0:  # 30 degrees or more from lying across in one pair: a jump
        assert lies_as_kept_turn(body, CAMERA_CENTRES, turns, body_axis(_turned_body(2, 90.0))) is strict
    if 20.0 < abs(degrees) % 90.0 < 70.0:  # tilted halfway: what the search itself still refuses
        assert not strict


def _kept_turn_estimator(turns: tuple[int, int], degrees: float):
    """An oracle-session estimator tracking a person through crops turned ``turns``, and that person's joints
    turned ``degrees`` about the rig's z axis (across the views) through their centroid: (estimator, rig, joints)."""
    from benchmarks.measure_lying_rendered import rotation
    from ghnerf_runtime.joints3d import Joints3D

    est, rig, joints = _tracked_through(turns)
    est._turn_check_wait = 3  # a strong pass between the upright checks
    centre = joints.mean(axis=0)
    n = len(joints)

    def rolled(deg: float) -> Joints3D:
        points = (joints - centre) @ rotation(2, deg).T + centre
        return Joints3D(points, np.ones(n, np.float32), np.ones(n, bool), np.zeros((n, 2), np.float32))

    return est, rig, rolled(degrees), rolled


@pytest.mark.parametrize("turns, degrees, before, kept", [
    ((90, 90), 60.0, 65.0, True), ((180, 180), 140.0, 145.0, True),
    ((90, 90), 25.0, 30.0, False),  # nearly up: upright crops read it better
    ((90, 90), 125.0, 90.0, False),  # 35 degrees in a pair from lying across: a jump, not a roll
    ((90, 90), 60.0, None, False),  # no pass kept through the turn to roll on from
])
def test_a_tracked_person_rolling_on_through_a_kept_turn_keeps_it(turns, degrees, before, kept):
    """A strong tracked pass through a kept turn of a person rolled 60 degrees from upright, 5 degrees more upright
    than the pass before (getting up from lying across the view), or 140 (a cartwheel through a half turn): before,
    the search's windows (level or upside down within 20 degrees) refused it as a misread, and the pair was read cold
    through upright crops, which read such a person worse (benchmarks/measure_lying_rendered.py --rolls). Now the
    turn holds while the body rolls on within 45 degrees of it; one nearly up, one jumped to, is still read cold
    upright."""
    from ghnerf_runtime.body_lie import body_axis
    from ghnerf_runtime.estimator import _Pass

    est, rig, body, rolled = _kept_turn_estimator(turns, degrees)
    est._kept_axis = None if before is None else body_axis(rolled(before))
    names = est.camera_names
    J = len(body.points)
    frame_reason = {n: None for n in names}
    asked = []

    def spy(images, regions, sequence, timing, novel_view=None, cold_several=None):
        asked.append((est._turns, regions.tracked))
        if est._turns == turns:  # the turned crops: the rolled person, found confidently
            return _Pass(regions, frame_reason, j3=body, someone=True,
                         joints_2d={n: np.zeros((J, 2)) for n in names},
                         conf_2d={n: np.ones(J, np.float32) for n in names},
                         missing_2d={n: np.zeros(J, bool) for n in names})
        return _Pass(regions, frame_reason)  # upright, from the working volume: nobody

    est._pass = spy
    images = [np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair]
    r = est.estimate(images)
    if kept:
        assert asked == [(turns, True)], asked
        assert not r.missing.any() and r.tracked and est._turns == turns and est.turns_refused == 0
        np.testing.assert_allclose(est._kept_axis, body_axis(body))  # the next pass rolls on from this one
    else:
        assert asked == [(turns, True), ((0, 0), False)], asked
        assert r.missing.all() and est._turns == (0, 0) and est.turns_refused == 1


def _found(est, regions, j3):
    """A pass over ``regions`` that found the person ``j3`` confidently in both views."""
    from ghnerf_runtime.estimator import _Pass

    names = est.camera_names
    J = len(j3.points)
    return _Pass(regions, {n: None for n in names}, j3=j3, someone=True,
                 joints_2d={n: np.zeros((J, 2)) for n in names},
                 conf_2d={n: np.ones(J, np.float32) for n in names},
                 missing_2d={n: np.zeros(J, bool) for n in names})


@pytest.mark.parametrize("degrees, misreads", [(60.0, False), (125.0, True)])
def test_asking_whether_a_kept_turns_pass_misreads_changes_nothing(degrees, misreads):
    """``Estimator._turn_misreads`` only answers: before, a pass it let through moved the stored axis the next pass
    rolls on from (and one it refused counted in ``turns_refused``) as the question was asked, so a caller that
    asked without keeping the pass, or asked twice, changed what the next pair is measured against. Now the axis is
    set once a pair, from the pass it keeps (``_kept_turn_axis``), and the refusal is counted where it is made.
    60 degrees rolls on 5 from the pass before; 125 jumps 35 from lying across (refused)."""
    from ghnerf_runtime.body_lie import body_axis

    est, rig, body, rolled = _kept_turn_estimator((90, 90), degrees)
    before = body_axis(rolled(65.0 if degrees == 60.0 else 90.0))
    est._kept_axis = before.copy()
    p = _found(est, est.tracker.regions(), body)
    assert [est._turn_misreads(p), est._turn_misreads(p)] == [misreads, misreads]
    np.testing.assert_array_equal(est._kept_axis, before)
    assert est.turns_refused == 0


def test_a_kept_turns_roll_is_not_measured_against_a_pass_pairs_old():
    """The step limit of a kept turn's roll (25 degrees, ``KEPT_TURN_STEP_DEG``) was measured pair to pair. Before,
    a pair through the kept turn that kept no pass (one camera's frame rejected, here) left the stored axis as it
    was, and the next pass was measured against one two pairs old (or many, after a stretch seen by one camera) as
    if it were the last pair's: a limit of one pair's roll over several, which a real roll may pass and a misread
    may not. Now a pair that keeps no pass through the turn drops the axis, and the next pass is asked the search's
    rule (a body tilted 60 degrees fails its windows: refused, the pair read cold upright, as with no pass before)."""
    from ghnerf_runtime.body_lie import body_axis
    from ghnerf_runtime.estimator import _Pass

    est, rig, body, rolled = _kept_turn_estimator((90, 90), 60.0)
    est._kept_axis = body_axis(rolled(65.0))  # the pair before kept the person 5 degrees less rolled
    names = est.camera_names
    asked, passes = [], iter([
        lambda regions: _Pass(regions, {names[0]: None, names[1]: "flat"}),  # this pair: one view rejected
        lambda regions: _found(est, regions, body),  # the next: the person rolled on, seen by both
    ])
    nobody = {n: None for n in names}

    def spy(images, regions, sequence, timing, novel_view=None, cold_several=None):
        asked.append((est._turns, regions.tracked))
        if est._turns == (90, 90):
            return next(passes)(regions)
        return _Pass(regions, nobody)  # upright, from the working volume: nobody

    est._pass = spy
    images = [np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair]
    r = est.estimate(images)
    assert asked == [((90, 90), True)] and r.missing.all() and est._turns == (90, 90)
    assert est._kept_axis is None  # the pair kept no pass through the turn
    asked.clear()
    r = est.estimate(images)
    assert asked == [((90, 90), True), ((0, 0), False)], asked
    assert r.missing.all() and est._turns == (0, 0) and est.turns_refused == 1


def _weak_cold_pairs(reads, keeps=()):
    """An oracle-session estimator (no model, the turn search on at ``turn_search_every`` 5) whose upright passes
    read, pair after pair, ``reads``: a body's joints (someone found, weakly: every pass here is weak) or ``None``
    (nobody found); no pass leaves a track, so every pair is cold, and every search keeps no turn but those of the
    pairs (1-based) in ``keeps``, which keep a pass that found the body lying. Returns the pairs (1-based) that
    searched."""
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator, _Pass

    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    est = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(roi=RoiConfig(turn_search=True)))
    assert est.config.roi.turn_search_every == 5
    names = est.camera_names
    nobody = {n: None for n in names}
    now, searched = {}, []
    est._pass = lambda images, regions, *a, **k: (_Pass(regions, nobody) if now["j3"] is None
                                                  else _found(est, regions, now["j3"]))
    est._weak_pass = lambda p: True  # weakly read (or nobody), someone may be there

    def search(images, p, sequence, timing, novel_view, track=None, rolled_from=None):
        searched.append(sequence + 1)
        if sequence + 1 in keeps:
            return _found(est, p.regions, _tilted(90.0))  # a turn kept
        return p  # no turn kept

    est._turn_search = search
    images = [np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair]
    for i, j3 in enumerate(reads):
        now["j3"] = j3
        est.estimate(images, sequence=i)
    return searched


def _tilted(degrees: float):
    """A person rolled ``degrees`` from upright across the view (about the rig's z axis)."""
    return _turned_body(2, degrees)


@pytest.mark.parametrize("reads, searched", [
    # lying down: read at 45 and 48 degrees, then lost by the upright crops (past 60-70 degrees, where a turn begins
    # to read the body): the first pair that finds nobody searches at once; the wait runs on from the failed search
    # (an early search does not restart it), so the sixth pair searches as before
    ([45, 48, None, None, None, None, None], [1, 3, 6]),
    # lost, found again, lost again: the early search's own pass found nobody, so only one early search
    ([45, None, None, 50, None, None, None], [1, 2, 6]),
    # the same misread body pair after pair (a person lying along a line of sight): only every fifth searches
    ([45, 47, 43, 46, 44, 45, 47], [1, 6]),
    # rolling on, still found: the body axis alone does not search early (tried: more searches, no turn sooner)
    ([40, 46, 58, 61, 64, 67], [1, 6]),
    # nobody found at the failed search: nothing lost since, every fifth
    ([None, None, 45, None, None, None, None], [1, 6]),
])
def test_a_weak_pair_in_the_wait_searches_when_it_lost_the_failed_searchs_person(reads, searched):
    """After a search that kept no turn, the next four weak pairs did not search (``roi.turn_search_every`` 5): for
    a person no turn rights, three encoder runs a pair for nothing. A person lying down or turning a cartwheel,
    read weakly upright up to 60-70 degrees and searched for there in vain, rolled into the tilts a turn reads
    during that wait, where the upright crops lose them, and was found up to four pairs late
    (benchmarks/measure_lying_rendered.py --rolls: roll_down 60-90 degrees 56.9 % of the joints found). Now a weak
    pair in the wait that finds nobody where the failed search's pass found someone searches at once."""
    reads = [None if d is None else _tilted(d) for d in reads]
    assert _weak_cold_pairs(reads) == searched


def _searches_with_turned_reads(turned_reads):
    """An oracle-session estimator (no model, the turn search on at ``turn_search_every`` 5) whose upright passes
    find nobody, pair after pair, and whose turned passes (the one turn ``(90, 90)`` the search tries) read, pair
    after pair, a body rolled ``turned_reads[i]`` degrees across the view (about the rig's z axis): the search's own
    code runs, with its body-lie rule and its refusals. Returns the pairs (1-based) that searched."""
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator, _Pass

    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    est = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(roi=RoiConfig(turn_search=True)))
    assert est.config.roi.turn_search_every == 5
    names = est.camera_names
    heat = {"encoder_heatmaps": np.zeros((2, 25, 4, 4), np.float32)}
    now, searched = {}, []

    def one_pass(images, regions, *a, **k):
        if est._turns == (0, 0):
            return _Pass(regions, {n: None for n in names}, env=heat)  # nobody found upright
        return replace(_found(est, regions, _tilted(now["deg"])), env=heat)

    est._pass = one_pass
    est._weak_pass = lambda p: True
    est._turn_candidates = lambda images, base, timing, track=None: [(90, 90)]
    search = est._turn_search

    def counted(images, p, sequence, *a, **k):
        searched.append(sequence + 1)
        return search(images, p, sequence, *a, **k)

    est._turn_search = counted
    images = [np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair]
    for i, deg in enumerate(turned_reads):
        now["deg"] = deg
        est.estimate(images, sequence=i)
    assert est.turns_kept == 0
    return searched


@pytest.mark.parametrize("turned_reads, searched", [
    # lying down, lost by the upright crops, read through the quarter turn 65 degrees from upright (5 short of the
    # lying window): refused, but the next pair searches at once; the wait runs on from the failed search
    ([65, 68, 68, 68, 68, 68, 68], [1, 2, 3, 6, 7]),
    # ... and again while each early search reads the body at least 2 degrees nearer the window (rolling in: 3 degrees
    # a pair lying down), not when it stays
    ([62, 65, 68, 69, 69, 69, 69, 69], [1, 2, 3, 4, 6, 7]),
    # a body that stays there (propped on an elbow) searches twice in five pairs, not every pair
    ([66, 66, 66, 66, 66, 66, 66], [1, 2, 6, 7]),
    # further from lying (still bending over): the wait as before
    ([50, 52, 54, 56, 58, 59, 59], [1, 6]),
    # the turned reads of a person lying along a line of sight (past lying toward upside down, across the views):
    # the wait as before
    ([135, 135, 135, 135, 135, 135, 135], [1, 6]),
])
def test_a_failed_search_that_refused_a_body_nearly_lying_searches_again_at_once(turned_reads, searched):
    """The search's upright pass found nobody (a person lying down, lost by the upright crops past 60-70 degrees),
    its turned pass read the body 54-69 degrees from upright and was refused (not yet level within
    ``TURN_LIE_TOLERANCE_DEG``), and the next four weak pairs waited, the body rolling into the window meanwhile
    (benchmarks/measure_lying_rendered.py --rolls: docs/turn-search.md, "A body nearly lying"). Now the next weak
    pair searches at once, and the next after it while the body rolls nearer the window (by at least 2 degrees
    from search to search)."""
    assert _searches_with_turned_reads(turned_reads) == searched


def test_a_turn_kept_by_an_early_search_ends_the_wait():
    """A search the wait let through early (``_searches_early``) that kept a turn left the wait running, and its
    trigger set: the tracked pairs through the turn never ended it, so when the turn was lost the next search counted
    as an early one, and the wait it left ran from the old search, not its own (the cartwheel past 150 degrees in
    benchmarks/measure_lying_rendered.py --rolls: docs/turn-search.md, "A body nearly lying"). A kept turn ends the
    wait, as a pair that finds someone well does: the search after it starts a wait of its own, four weak pairs."""
    reads = [_tilted(45.0)] + [None] * 7  # found weakly, then lost: the second pair searches early, and keeps a turn
    assert _weak_cold_pairs(reads, keeps={2}) == [1, 2, 3, 8]


def _lost_turn_pair(lost: tuple[int, int], kept_deg: float, upright_deg: float, tried: tuple[int, int],
                    tried_deg: float):
    """One pair of an oracle-session estimator (no model, the turn search on) tracking a person through crops turned
    ``lost``, the last pass kept through them ``kept_deg`` from upright (rolled across the views, about the rig's z
    axis). This pair's tracked pass through them finds nobody and drops the track; the cold upright pass finds the
    body read ``upright_deg`` from upright, strongly (every joint at confidence 1: not a weak pass); a search tries
    ``tried`` only, whose pass reads it ``tried_deg``, as confidently. Returns (estimator, the searches run)."""
    from ghnerf_runtime.body_lie import body_axis
    from ghnerf_runtime.estimator import _Pass

    est, rig, body, rolled = _kept_turn_estimator(lost, kept_deg)
    est._kept_axis = body_axis(body)
    heat = {"encoder_heatmaps": np.zeros((2, 25, 4, 4), np.float32)}
    searched = []

    def one_pass(images, regions, *a, **k):
        if est._turns == lost and regions.tracked:
            est.tracker.reset()  # the turned track lost the person
            return _Pass(regions, {n: None for n in est.camera_names}, env=heat)
        deg = upright_deg if est._turns == (0, 0) else tried_deg
        return replace(_found(est, regions, rolled(deg)), env=heat)

    est._pass = one_pass
    est._turn_candidates = lambda images, base, timing, track=None: [tried]
    search = est._turn_search

    def counted(*a, **k):
        searched.append(est._turns)
        return search(*a, **k)

    est._turn_search = counted
    est.estimate([np.zeros((c.size[1], c.size[0], 3), np.uint8) for c in rig.pair])
    return est, searched


@pytest.mark.parametrize("lost, kept_deg, upright_deg, tried, tried_deg, searched, turns", [
    # the cartwheel past 135 degrees loses the quarter turn; upright reads it standing, feet where the head is (150
    # degrees from the kept pass): a search, and the half turn that reads it rolled on 20 degrees is kept
    ((90, 90), 135.0, -15.0, (180, 180), 155.0, True, (180, 180)),
    # the half turn reads it 120 degrees from upright: outside that turn's sector (135-180), and short of the
    # search's windows, so upright stands
    ((90, 90), 135.0, -15.0, (180, 180), 120.0, True, (0, 0)),
    # upright reads the body as the turn left it (20 degrees on): no misread, a strong pass, no search
    ((90, 90), 135.0, 155.0, (180, 180), 155.0, False, (0, 0)),
    # someone lying across the view who stood up: 90 degrees from the kept pass, not turned over, no search
    ((90, 90), 90.0, 0.0, (90, 90), 90.0, False, (0, 0)),
    # getting up from upside down: read turned over upright, but no other turn lies near enough to keep a roll on
    # from 175 degrees (the quarter turn's sector ends at 135): a strong pass, no search
    ((180, 180), 175.0, 0.0, (180, 180), 178.0, False, (0, 0)),
])
def test_a_strong_upright_read_turned_over_against_a_lost_turn_searches(lost, kept_deg, upright_deg, tried,
                                                                         tried_deg, searched, turns):
    """A cartwheel kept through the quarter turn past 135 degrees lost it; the upright crops read the body nearly
    upside down as someone standing at a median confidence of 0.50 (bench scene 10 in
    benchmarks/measure_lying_rendered.py --rolls cartwheel), a strong pass, so nothing searched, and a later weak
    pair's search refused the half turn, which read the body no 0.1 more confidently (docs/turn-search.md, "A turn
    lost past 135 degrees"). Now an upright pass turned over against the lost turn's last kept pass searches, and a
    pass through another turn that rolled on from that pass is kept."""
    est, runs = _lost_turn_pair(lost, kept_deg, upright_deg, tried, tried_deg)
    assert bool(runs) is searched and est._turns == turns
    assert est.turns_kept == (turns != (0, 0))
