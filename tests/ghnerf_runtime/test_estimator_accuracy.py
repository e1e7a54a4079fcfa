"""End-to-end accuracy of the *shipped* model (models/) on held-out simulator sequences.

Skips until the trained model lands (models/model_card.json). The thresholds are the figures
measured with benchmarks/compare_3d_methods.py on the same sequences (docs/runtime.md) plus a
margin; re-measure and update them whenever models/ changes.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig, HeatmapsConfig, Joints3DConfig, SessionConfig, \
    TrackingConfig

#: Tests that watch the first pair itself (cold, then tracked) keep it unrefined (refined, the default since
#: session 48, it reports its second, tracked pass).
COLD = TrackingConfig(refine_cold_start=False)

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"  # the shipped layout: models/ghnerf/<graph>.onnx, models/model_card.json

#: Measured with exactly this test's sequences on the shipped model (MEASURED_ON), per heatmap source with
#: its default 3D method, by ``ghnerf-bench runtime --sequences 4 --frames 10 --warmup 0 --precisions auto
#: --modes keypoints --heatmap-sources rendered,encoder``; the thresholds add margins (pairs are few: 40).
#: Set a value to None to check sanity only. Re-measure when models/ changes.
MEASURED_ON = ("models/ of 2026-11-22, session 15 (the tenth, `--recipe gpu`: the ninth's recipe with the human "
               "encoder's trunk at 128x128, pretrained 27000 steps of 4 scenes on an H100; 10000 joint steps; "
               "ghnerf-eval PCK@0.2 0.944 rendered / 0.968 encoder heatmaps on 256 val scenes, int8)")
#: measured (crop margin 0.125): rendered/depth_centroid PCK@0.2 0.914, MPJPE 158 mm, 96 % of 3D joints
#:           found (presence gate 0.4; tracking.follow_encoder, the default);
#:           encoder/triangulate    PCK@0.2 0.930, MPJPE 103 mm, 58 % found (presence gate 0.35; this model
#:           leaves a joint hidden in one view undecoded there, as its training targets do: docs/runtime.md).
#:           encoder with the flip test (--flip-tests off,on): PCK@0.2 0.935, MPJPE 97 mm, 60 % found; it is
#:           held to the encoder's thresholds.
#: (the ninth model, `make model` on two cores: rendered 0.898 / 166 mm / 99 %, encoder 0.886 / 118 mm / 66 %,
#:  flip test 0.909 / 110 mm; the seventh: rendered 0.791 / 223 mm / 99 %, encoder 0.906 / 139 mm / 68 %.)
#: With the skeleton prior (session 17, models/ghnerf/skeleton_prior.onnx: feature version 2, two networks, run
#: with their flip test; the default ``joints3d.max_prior_error_m`` 0.15; ``--flip-tests off,on
#: --skeleton-priors off,on`` added to the command above): flip test PCK@0.2 0.947, MPJPE 38.0 mm, 97 % found
#: (hidden joints 38.6 mm, 97 % found); without the (heatmaps') flip test 0.953 / 41.0 mm / 97 %. The rows
#: without the prior measured as above in the same run. (Session 16's one-network prior without its own flip
#: test: 0.952 / 41.9 mm / 96 %.)
THRESHOLDS = {
    "rendered": {"pck@0.2_min": 0.86, "mpjpe_mm_max": 195.0, "found_3d_min": 0.90},
    "encoder": {"pck@0.2_min": 0.88, "mpjpe_mm_max": 125.0, "found_3d_min": 0.52},
    "encoder+prior": {"pck@0.2_min": 0.88, "mpjpe_mm_max": 60.0, "found_3d_min": 0.88},
}
METHODS = {"rendered": "depth_centroid", "encoder": "triangulate"}
SEQUENCES, FRAMES = 4, 10
#: A view of a textured empty room is far from flat (the frame check's floor is 2 levels of standard deviation); the
#: black frames these tests used until session 65 (the person put 40 m away took the room along) had 0.9.
TEXTURED_STD_MIN = 5.0


def textured_empty_room(rig, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Scene ``seed``'s room with nobody in it, as ``rig.pair`` sees it at 0.2 s (``benchmarks/empty_rooms.py``),
    checked to be a textured room and not black frames."""
    from benchmarks.empty_rooms import empty_room_pair

    pair = empty_room_pair(rig, seed, 0.2)
    assert all(image.std() > TEXTURED_STD_MIN for image in pair), [image.std() for image in pair]
    return pair


pytestmark = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                reason="no trained model yet: models/model_card.json does not exist (the trained "
                                       "GHNeRF lands in models/; random-weight accuracy is meaningless)")


@pytest.mark.parametrize("source, flip, prior", [("rendered", False, "auto"), ("encoder", False, "off"),
                                                ("encoder", True, "off"), ("encoder", True, "on")])
def test_shipped_model_on_held_out_sequences(source, flip, prior):
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.bench import run_pairs
    from ghnerf_runtime.cli.simdata import Accuracy, load_sequences
    from ghnerf_runtime.estimator import Estimator

    sequences = load_sequences(SEQUENCES, FRAMES)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128),
                          heatmaps=HeatmapsConfig(source=source, flip_test=flip),
                          joints3d=Joints3DConfig(method=METHODS[source], skeleton_prior=prior))
    est = Estimator.from_config(sequences[0].rig, cfg)
    assert (est.skeleton_prior is not None) == (prior == "on")
    acc = Accuracy()
    run_pairs(est, sequences, novel=False, warmup=0, accuracy=acc)
    s = acc.summary()
    assert np.isfinite(s["pck@0.2"]) and s["pck_evaluated"] > 0
    t = THRESHOLDS["encoder+prior" if prior == "on" else source]
    if t["pck@0.2_min"] is not None:
        assert s["pck@0.2"] >= t["pck@0.2_min"], s
    if t["mpjpe_mm_max"] is not None:
        assert s["mpjpe_mm"] <= t["mpjpe_mm_max"], s
    if t["found_3d_min"] is not None:
        assert s["found_3d_frac"] >= t["found_3d_min"], s
    by = s["mpjpe_by_visibility"]
    assert sum(c["joints"] for c in by.values()) == s["mpjpe_evaluated"]
    if prior == "on":
        # the prior places the joints no camera sees nearly as well as the seen ones (46.9 mm, 97 % found)
        assert by["no_view"]["found"] >= 0.7 and by["no_view"]["mpjpe_mm"] <= 80.0, by
        return
    # joints both cameras see are placed better than joints neither sees (measured 103 / 232 mm encoder,
    # 183 / 267 mm rendered): a split attached to the wrong joints or views would not keep this order
    assert by["all_views"]["mpjpe_mm"] < by["no_view"]["mpjpe_mm"], by
    # and the reported confidence says so (30 bench sequences, flip test: medians 0.64 / 0.54 / 0.37)
    assert by["all_views"]["confidence_median"] > by["no_view"]["confidence_median"], by


@pytest.mark.parametrize("source, flip, prior", [("encoder", False, "auto"), ("rendered", False, "auto"),
                                                ("encoder", True, "auto"), ("encoder", True, "off")])
def test_shipped_model_finds_nobody_in_an_empty_room(source, flip, prior):
    """No hallucinated person: the trained heatmaps of an empty room (textured, as a real one; the frame check off,
    so the model's own answer is asked) decode to no joints at all (also with
    the flip test, whose averaged heatmaps the same presence gate judges, and with the skeleton prior, which
    would place a skeleton in any noise: the gate asks the peaks, not the prior)."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.estimator import Estimator

    rig = sim.RigPlacement().build()
    # the frame check off: the model itself must say "nobody" (the check may reject plain walls first)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS)),
                          heatmaps=HeatmapsConfig(source=source, flip_test=flip),
                          joints3d=Joints3DConfig(method=METHODS[source], skeleton_prior=prior),
                          frame_check=FrameCheckConfig(enabled=False))
    est = Estimator.from_config(rig, cfg)
    assert (est.skeleton_prior is not None) == (source == "encoder" and prior == "auto")
    for seed in (1, 2):
        pair = textured_empty_room(rig, seed)
        for _ in range(2):  # cold, then whatever track the first pair left
            r = est.estimate(pair)
            assert r.num_found == 0 and not r.confidence.any() and not r.joints_3d.any()


@pytest.mark.parametrize("skip_below", [0.1, 0.0])
def test_the_flip_test_runs_only_where_someone_may_be(skip_below):
    """``heatmaps.flip_test_skip_below``: an empty room costs one encoder run, not two, and still finds nobody;
    a pair with a person runs the mirrored pass; 0 runs it always, the empty room then judged on the average."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator

    rig = sim.RigPlacement().build()
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS)),
                          heatmaps=HeatmapsConfig(flip_test=True, flip_test_skip_below=skip_below),
                          frame_check=FrameCheckConfig(enabled=False))
    est = Estimator.from_config(rig, cfg)
    r = est.estimate(textured_empty_room(rig, 3))
    assert r.num_found == 0 and not r.confidence.any()
    assert ("encoder_flip" in r.timing_ms) == (skip_below == 0), r.timing_ms
    seq = load_sequences(1, 2)[0]
    est = Estimator(est.session, seq.rig, cfg)
    r = est.estimate((np.asarray(seq.images[0, 0]), np.asarray(seq.images[0, 1])))
    assert r.num_found > 0 and "encoder_flip" in r.timing_ms, r.timing_ms


def test_the_flip_test_side_by_side_gives_the_same_joints():
    """heatmaps.flip_test_side_by_side: on tracked pairs the crops and their mirror images run side by side (no
    encoder_flip stage: one encoder time for both); every joint, 2D and 3D, is what the runs in turn give."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator, load_session

    seq = load_sequences(1, 4)[0]
    results = {}
    for side in (True, False):
        cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), threads=2),
                              heatmaps=HeatmapsConfig(flip_test_side_by_side=side), tracking=COLD)
        est = Estimator(load_session(cfg), seq.rig, cfg)
        results[side] = [est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])), sequence=i,
                                      timestamp_s=i / 30) for i in range(len(seq))]
    for i, (a, b) in enumerate(zip(results[True], results[False])):
        assert np.array_equal(a.joints_3d, b.joints_3d) and np.array_equal(a.missing, b.missing), i
        assert all(np.array_equal(a.joints_2d[c], b.joints_2d[c]) for c in a.joints_2d), i
        assert ("encoder_flip" in a.timing_ms) == (not a.tracked) and "encoder_flip" in b.timing_ms, i
    assert sum(r.tracked for r in results[True]) >= 3 and results[True][-1].num_found > 20


class _NoLanes:
    """The session without its one-thread lanes: every graph on its own two-thread session, in turn."""

    def __init__(self, session) -> None:
        self._session = session
        self.contract, self.skeleton_prior, self.novel_painter = (session.contract, session.skeleton_prior,
                                                                  session.novel_painter)

    def has(self, graph: str) -> bool:
        return self._session.has(graph)

    def run(self, graph: str, feeds):
        return self._session.run(graph, feeds)


def test_novel_views_on_lanes_and_through_the_pipeline_are_the_same_pictures():
    """With a novel view, a tracked pair's view starts rendering once the encoder graph has run, on one-thread
    lanes (``ModelSession.on_lanes``), with the flip test's run beside it on the ``human`` lane; and
    ``NovelViewPipeline`` finishes each view while the next pair is estimated. Neither changes a number: every
    joint and every pixel of the view is what the graphs run in turn on their two-thread sessions give."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.config import NovelViewConfig
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.novel_view import NovelViewRequest
    from ghnerf_runtime.pipeline import NovelViewPipeline

    seq = load_sequences(1, 6)[0]
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), threads=2),
                          novel_view=NovelViewConfig(enabled=True))
    session = load_session(cfg)
    request = NovelViewRequest(alpha=0.3, overlay="skeleton")
    pairs = [(np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])) for i in range(len(seq))]
    runs = {}
    for name, sess in (("lanes", session), ("in turn", _NoLanes(session))):
        with Estimator(sess, seq.rig, cfg) as est:
            assert est._novel_lanes == (name == "lanes")
            runs[name] = [est.estimate(p, sequence=i, novel_view=request, timestamp_s=i / 30)
                          for i, p in enumerate(pairs)]
    with Estimator(session, seq.rig, cfg) as est, NovelViewPipeline(est) as pipe:
        out = [pipe.submit(p, sequence=i, novel_view=request, timestamp_s=i / 30) for i, p in enumerate(pairs)]
        assert out[0] == [] and all(len(o) == 1 for o in out[1:])  # one pair in flight
        runs["pipeline"] = [r for o in out for r in o] + pipe.flush()
    assert sum(r.tracked for r in runs["in turn"]) >= 4 and runs["in turn"][-1].num_found > 20
    for name in ("lanes", "pipeline"):
        for i, (a, b) in enumerate(zip(runs[name], runs["in turn"], strict=True)):
            assert a.sequence == b.sequence == i and a.tracked == b.tracked, (name, i)
            assert np.array_equal(a.joints_3d, b.joints_3d) and np.array_equal(a.missing, b.missing), (name, i)
            assert all(np.array_equal(a.joints_2d[c], b.joints_2d[c]) for c in a.joints_2d), (name, i)
            assert np.array_equal(a.novel_view.image, b.novel_view.image), (name, i)
            assert np.array_equal(a.novel_view.depth, b.novel_view.depth), (name, i)
            assert a.novel_view.camera.P.tolist() == b.novel_view.camera.P.tolist(), (name, i)
            assert {"novel_render", "novel_proxy", "novel_matte", "total"} <= set(a.timing_ms), (name, i)
    assert session.run_counts["render_rgb"] > 0 and session.novel_painter is not None


def test_shipped_prior_gate_reports_fewer_3d_joints_not_fewer_people():
    """The skeleton prior's error gate decides which 3D joints are reported, not whether someone is there: with a
    gate no joint passes, the 2D joints are still reported and the crop still follows the prior's skeleton."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator

    seq = load_sequences(SEQUENCES, FRAMES)[0]
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS)),
                          joints3d=Joints3DConfig(skeleton_prior="on", max_prior_error_m=1e-6), tracking=COLD)
    est = Estimator.from_config(seq.rig, cfg)
    for i in range(len(seq)):
        r = est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])), sequence=i)
        assert r.missing.all(), i
        assert all((~m).sum() >= 10 for m in r.missing_2d.values()), i
        assert r.tracked == (i > 0), i


#: measured (this test's 40 pairs, the seventh model, `auto`, the default flip test): the uncovered camera's
#: PCK@0.2 0.937 (camera 0) / 0.901 (camera 1), every visible joint decoded (without the flip test 0.922 / 0.883);
#: a full pair's both views together 0.916 (above)
SINGLE_VIEW_PCK_MIN = 0.84


def test_shipped_model_with_one_camera_covered():
    """``frame_check.single_view_2d`` (the default): with one camera's frames black, the other camera's 2D
    joints come from its own heatmaps, its crop following them from pair to pair; no 3D joint. With nobody
    in the room, nothing (the presence gate on the uncovered view's peaks: its textured room reaches the model)."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.metrics import pck

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128))
    session = load_session(cfg)
    sequences = load_sequences(SEQUENCES, FRAMES)
    for good in (0, 1):
        pred, true, visible, found, followed = [], [], [], [], 0
        for seq in sequences:
            est = Estimator(session, seq.rig, cfg)
            name = est.camera_names[good]
            for i in range(len(seq)):
                pair = [np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])]
                pair[1 - good] = np.zeros_like(pair[1 - good])
                r = est.estimate(pair)
                assert r.missing.all() and r.missing_2d[est.camera_names[1 - good]].all()
                assert r.single_view == name, (good, i)  # the answer is the good camera's (session 53)
                pred.append(r.joints_2d[name])
                true.append(seq.joints_2d[i, good])
                visible.append(seq.visible[i, good])
                found.append(~r.missing_2d[name])
                followed += est.tracker.view_track is not None
        score = pck(np.array(pred), np.array(true), np.array(visible), pred_valid=np.array(found))
        assert score.value >= SINGLE_VIEW_PCK_MIN, (good, score)
        assert followed >= 0.9 * len(pred), "the good camera's crop follows its 2D joints"

    rig = sim.RigPlacement().build()
    est = Estimator(session, rig, cfg)
    for seed in (1, 2):
        for covered in (0, 1):
            pair = list(textured_empty_room(rig, seed))
            pair[covered] = np.zeros_like(pair[covered])
            est.reset()
            r = est.estimate(pair)
            # the covered camera is rejected, the other view's empty room goes to the model, which finds nobody there
            assert r.frame_ok == {est.camera_names[covered]: False, est.camera_names[1 - covered]: True}, r.frame_ok
            assert all(m.all() for m in r.missing_2d.values()) and r.missing.all() and r.single_view is None


def _bad_frames(shape: tuple[int, ...]) -> dict[str, tuple[str, np.ndarray]]:
    """The frames a broken camera gives, each with the frame check's word for it (``PairResult.frame_reason``)."""
    noise = np.random.default_rng(65).integers(0, 256, shape, dtype=np.uint8)
    return {"black": ("flat", np.zeros(shape, np.uint8)), "saturated": ("flat", np.full(shape, 255, np.uint8)),
            "noise": ("noise", noise)}


def test_the_other_view_leaves_a_views_encoder_heatmaps_alone():
    """The keypoint graph takes both crops in one batch, but each view's heatmaps depend on that view alone: a
    black, saturated or noise crop beside a good one changes none of the good one's values (session 65: a noise
    frame was reported to cost the good view accuracy; measured, the heatmaps are the same to the bit)."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator, load_session

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128))
    session = load_session(cfg)
    graph = "human" if session.has("human") else "encoder"
    seq = load_sequences(SEQUENCES, FRAMES)[0]
    est = Estimator(session, seq.rig, cfg)
    pair = [np.asarray(seq.images[0, 0]), np.asarray(seq.images[0, 1])]
    batch, _, _ = est._crop_batch(pair, est.tracker.volume_regions.rois)
    alone = session.run(graph, {"images": batch})["encoder_heatmaps"][0]
    for kind, (_, frame) in _bad_frames(pair[1].shape).items():
        beside, _, _ = est._crop_batch([pair[0], frame], est.tracker.volume_regions.rois)
        np.testing.assert_array_equal(session.run(graph, {"images": beside})["encoder_heatmaps"][0], alone,
                                      err_msg=kind)


@pytest.mark.parametrize("flip", [False, True])
def test_a_noise_frame_costs_the_good_view_what_a_black_one_does(flip):
    """With one camera's frames black, saturated or uniform noise, the frame check rejects them (``flat``,
    ``flat``, ``noise``) and the other camera's 2D joints are the same to the bit, pair after pair: the garbage
    view changes neither the good view's heatmaps, nor its presence gate, flip test or view track."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator, load_session

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128),
                          heatmaps=HeatmapsConfig(flip_test=flip))
    session = load_session(cfg)
    seq = load_sequences(SEQUENCES, FRAMES)[0]
    for good in (0, 1):
        answers = {}
        for kind, (word, frame) in _bad_frames(seq.images.shape[2:]).items():
            est = Estimator(session, seq.rig, cfg)
            good_name, bad_name = est.camera_names[good], est.camera_names[1 - good]
            answers[kind] = []
            for i in range(len(seq)):
                pair = [np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])]
                pair[1 - good] = frame
                r = est.estimate(pair)
                assert r.frame_reason[bad_name] == word and r.single_view == good_name, (kind, good, i)
                answers[kind].append((r.joints_2d[good_name], r.confidence_2d[good_name], r.missing_2d[good_name]))
            est.close()
        for kind, got in answers.items():
            for i, (mine, black) in enumerate(zip(got, answers["black"])):
                for a, b in zip(mine, black):
                    np.testing.assert_array_equal(a, b, err_msg=f"{kind} beside camera {good}, pair {i}")


#: measured (this test's 40 pairs, MEASURED_ON's model, the defaults with the frame check off; session 53,
#: ``benchmarks/measure_one_camera.py --sequences 4 --frames 10``): the seeing camera's PCK@0.2 0.961 (camera 0) /
#: 0.916 (camera 1), every pair answered with its 2D joints; held to SINGLE_VIEW_PCK_MIN, a covered camera's.
def test_shipped_model_with_a_person_seen_by_one_camera_only():
    """Someone seen by one camera, the other showing the same room without them (both frames pass, the model
    runs on both: the frame check off, as the simulator's plain walls would fail it): no 3D joint, the seeing
    camera's 2D joints (``single_view`` names it), as accurate as a covered camera's other view, and no pair
    searches the crop turns; the same rooms without anyone report nobody (benchmarks/measure_one_camera.py measures
    the bench's 300 pairs)."""
    pytest.importorskip("drivers.sim")
    from benchmarks.measure_one_camera import empty_counterpart
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.metrics import pck

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128),
                          frame_check=FrameCheckConfig(enabled=False))
    session = load_session(cfg)
    sequences = load_sequences(SEQUENCES, FRAMES)
    rooms = [empty_counterpart(seq) for seq in sequences]
    for seen in (0, 1):
        pred, true, visible, found, answered = [], [], [], [], 0
        for seq, room in zip(sequences, rooms):
            est = Estimator(session, seq.rig, cfg)
            name = est.camera_names[seen]
            for i in range(len(seq)):
                pair = [np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])]
                pair[1 - seen] = room[i][1 - seen]
                r = est.estimate(pair)
                assert r.missing.all() and r.missing_2d[est.camera_names[1 - seen]].all(), (seen, i)
                answered += r.single_view == name
                pred.append(r.joints_2d[name])
                true.append(seq.joints_2d[i, seen])
                visible.append(seq.visible[i, seen])
                found.append(~r.missing_2d[name])
            # roi.turn_search (on by default): the view reads them well, and a turn cannot find them in 3D (the
            # other view is empty); before session 57's fix every fifth pair searched, 8 of these 40 per camera
            assert est.turn_searches == 0, (seen, est.turn_searches)
        score = pck(np.array(pred), np.array(true), np.array(visible), pred_valid=np.array(found))
        assert score.value >= SINGLE_VIEW_PCK_MIN and answered == len(pred), (seen, score, answered)
    for seq, room in zip(sequences, rooms):
        est = Estimator(session, seq.rig, cfg)
        for i in range(len(seq)):
            r = est.estimate(room[i])
            assert r.single_view is None and all(m.all() for m in r.missing_2d.values()), i


def test_shipped_model_through_a_camera_dropout():
    """A camera blacked out for a few pairs mid-sequence: 2D joints from the other meanwhile, 3D joints again
    once it is back, and the 3D track again one pair later (the first pair back starts from the view track's
    crop in one camera and the working volume in the other)."""
    pytest.importorskip("drivers.sim")
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.estimator import Estimator

    seq = load_sequences(SEQUENCES, FRAMES)[0]
    est = Estimator.from_config(seq.rig, EstimatorConfig(session=SessionConfig(model_dir=str(MODELS)), tracking=COLD))
    names = est.camera_names
    dark = range(3, 6)
    for i in range(len(seq)):
        pair = [np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])]
        if i in dark:
            pair[1] = np.zeros_like(pair[1])
        r = est.estimate(pair, sequence=i)
        if i in dark:
            # view 0 keeps its 2D joints: at least those the truth marks visible there (11 of 25 here)
            seen = int(seq.visible[i, 0].sum())
            assert r.missing.all() and r.missing_2d[names[1]].all() and (~r.missing_2d[names[0]]).sum() >= seen, i
            assert est.tracker.view_track is not None and est.tracker.track is None
        else:
            assert r.num_found >= 10 and all(r.frame_ok.values()), i
            assert r.tracked == (i not in (0, dark.stop)), i


#: The device's novel view at the first rig camera's viewpoint, pairs 4 and 9 of this file's sequences, masked
#: PSNR against the simulator's picture (benchmarks/measure_novel_quality.py's measure): median 24.2 dB with the
#: runtime's default ``novel_view.opaque_at`` (0.5), 21.9 dB raw (1.0), on MEASURED_ON's model (the ninth: 24.7);
#: the seventh model, whose image features were normalised differently in training and at inference, scored about 16.
#: Those figures are of the rendered picture alone (``novel_view.proxy_blend`` off); the default recolouring from the
#: body proxy is checked to add to it.
NOVEL_PSNR_MEDIAN_MIN = 22.5


def test_shipped_models_novel_view_against_the_simulators_picture():
    pytest.importorskip("drivers.sim")
    from dataclasses import replace

    from benchmarks.bench_runtime_common import truth_view
    from drivers.sim import random_scene
    from ghnerf_runtime.cli.simdata import HELD_OUT_MOTIONS, load_sequences
    from ghnerf_runtime.config import NovelViewConfig
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.metrics import masked_psnr
    from ghnerf_runtime.novel_view import NovelViewRequest

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), expected_resolution=128),
                          novel_view=NovelViewConfig(enabled=True))
    session = load_session(cfg)
    psnr, whole, painted = {}, {}, []
    for opaque_at in (cfg.novel_view.opaque_at, 1.0, "proxy", "painter"):
        nv = replace(cfg.novel_view, painter="off", proxy_blend=False)
        if opaque_at == "proxy":
            nv = replace(nv, proxy_blend=True)
        elif opaque_at == "painter":  # at a rig camera's own viewpoint only when told to: the default skips it
            nv = replace(nv, proxy_blend=True, painter="on", painter_min_angle_deg=0.0)
        else:
            nv = replace(nv, opaque_at=opaque_at)
        run = replace(cfg, novel_view=nv)
        psnr[opaque_at], whole[opaque_at] = [], []
        for seq in load_sequences(SEQUENCES, FRAMES):
            scene = random_scene(int(seq.info["scene_seed"]), volume=seq.rig.volume, motions=HELD_OUT_MOTIONS)
            est = Estimator(session, seq.rig, run)
            for i in range(len(seq)):
                pair = (np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1]))
                r = est.estimate(pair, novel_view=NovelViewRequest(alpha=0.0) if i in (4, 9) else None)
                if r.novel_view is None:
                    continue
                t = float(seq.info["t0"]) + i / float(seq.info["fps"])
                truth, mask = truth_view(scene, r.novel_view.camera, t, float(session.contract.background))
                pred = r.novel_view.image[..., ::-1].astype(np.float64) / 255.0
                psnr[opaque_at].append(masked_psnr(pred, truth, mask).value)
                whole[opaque_at].append(masked_psnr(pred, truth, np.ones_like(mask)).value)
                painted.append(("novel_paint" in r.timing_ms) == (opaque_at == "painter"))
    shown, raw = np.array(psnr[cfg.novel_view.opaque_at]), np.array(psnr[1.0])
    assert len(shown) == len(raw) >= 6, psnr  # a view for nearly every scored pair
    assert np.median(shown) >= NOVEL_PSNR_MEDIAN_MIN, psnr
    assert np.all(shown > raw), psnr  # un-dimming the translucent subject helps every view
    assert np.median(psnr["proxy"]) > np.median(shown) + 0.5, psnr  # the proxy's colours help (docs/novel-view.md)
    # the learnt painter (novel_painter.onnx), forced on at the rig's viewpoint where it is not needed: it runs,
    # and costs at most a little there (held out, 30 sequences: 28.55 -> 28.24 dB median; docs/novel-view.md)
    assert all(painted) and len(psnr["painter"]) == len(shown)  # it ran on those views, and only there
    assert np.median(psnr["painter"]) > np.median(psnr["proxy"]) - 1.0, psnr
    # over the whole view the painter leaves the fog around the subject dark (session 30's painted it brighter)
    assert np.median(whole["painter"]) > np.median(whole["proxy"]) - 0.25, whole
