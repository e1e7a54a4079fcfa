"""ZJU-MoCap format: a tiny subject written from the simulator, read back, turned into samples."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from drivers.sim import SceneConfig, SimScene
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at
from training.data.cache import ShardedSplit
from training.data.errors import DataConfigError, DatasetError
from training.data.sample import check_sample
from training.data.zju import ANNOTS, ZjuFrame, ZjuSequence, write_zju_format
from training.data.zju_samples import ZjuConfig, convert_zju, zju_sample

SIZE, RES = 240, 64
TIMES = (0.1, 0.6)


def _ring(n: int = 4) -> list[Camera]:
    centre = np.array([0.0, -0.9, 3.0])
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = centre + 3.0 * np.array([np.sin(a), -0.15, -np.cos(a)])
        R, t = look_at(eye, centre)
        dist = [-0.08, 0.02, 0.001, -0.001, 0.003] if i % 2 else np.zeros(5)  # odd cameras have a lens
        cams.append(Camera(f"c{i}", SIZE, SIZE, intrinsics_from_fov(SIZE, SIZE, 62.0), dist, R, t))
    return cams


@pytest.fixture(scope="module")
def subject(tmp_path_factory):
    scene = SimScene(SceneConfig(seed=11, motion="squat"))
    cams = _ring()
    frames = []
    for t in TIMES:
        rendered = scene.render_batch(cams, t)
        kp = np.stack([np.concatenate([tr.joints_2d, tr.visible[:, None].astype(float)], 1) for _, tr in rendered])
        j3 = np.concatenate([scene.joints_3d(t), np.ones((25, 1))], 1)
        j3[3, 3] = 0.0  # one joint unlabelled
        frames.append(ZjuFrame([im for im, _ in rendered], [tr.mask for _, tr in rendered], kp, j3))
    root = write_zju_format(tmp_path_factory.mktemp("zju") / "CoreView_sim", cams, frames, image_ext=".png")
    return root, cams, frames


def test_written_layout_is_the_zju_layout(subject):
    root, cams, _ = subject
    annots = np.load(root / ANNOTS, allow_pickle=True).item()
    assert set(annots) == {"cams", "ims"} and set(annots["cams"]) == {"K", "R", "T", "D"}
    assert np.asarray(annots["cams"]["T"][1]).shape == (3, 1) and np.asarray(annots["cams"]["D"][1]).shape == (5, 1)
    # Millimetres on disk.
    assert np.allclose(np.asarray(annots["cams"]["T"][2]).ravel(), cams[2].t * 1000.0)
    assert annots["ims"][1]["ims"][2] == "Camera_B3/000001.png"
    assert np.asarray(annots["ims"][0]["kpts2d"]).shape == (4, 25, 3)
    assert (root / "mask" / "Camera_B3" / "000001.png").is_file()
    assert json.loads((root / "keypoints3d" / "000001.json").read_text())[0]["id"] == 0


def test_round_trip_of_every_value(subject):
    root, cams, frames = subject
    seq = ZjuSequence(root)
    assert (seq.num_frames, seq.num_cameras) == (len(TIMES), len(cams))
    for c, cam in enumerate(cams):
        back = seq.camera(c)
        assert np.array_equal(back.K, cam.K) and np.array_equal(back.R, cam.R) and np.array_equal(back.dist, cam.dist)
        assert np.allclose(back.t, cam.t, rtol=0, atol=1e-12)  # mm -> m
        assert back.size == cam.size and back.name == f"Camera_B{c + 1}"
    for f, frame in enumerate(frames):
        kp = seq.keypoints2d(f)
        assert np.array_equal(kp, frame.kpts2d)
        assert np.array_equal(seq.joints_3d(f), frame.joints_3d)
        for c in range(len(cams)):
            assert np.array_equal(seq.read_image(f, c), frame.images[c])
            assert np.array_equal(seq.read_mask(f, c), frame.masks[c])


def test_keypoints2d_json_fallbacks(tmp_path, subject):
    _, cams, frames = subject
    frame = frames[0]
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(frame.images[:2], frame.masks[:2])], image_ext=".png")
    seq = ZjuSequence(root)
    assert seq.keypoints2d(0) is None and seq.joints_3d(0) is None
    openpose = {"people": [{"pose_keypoints_2d": frame.kpts2d[0].ravel().tolist()}]}
    easymocap = {"annots": [{"personID": 0, "bbox": [0, 0, 1, 1, 1], "keypoints": frame.kpts2d[1].tolist()}]}
    for c, data in enumerate((openpose, easymocap)):
        path = root / "keypoints2d" / f"Camera_B{c + 1}" / "000000.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data))
    assert np.array_equal(seq.keypoints2d(0), frame.kpts2d[:2])


def test_samples_are_geometrically_consistent(subject):
    root, _, _ = subject
    seq = ZjuSequence(root)
    config = ZjuConfig(resolution=RES, view_sets=((0, 1, 2),))
    sample = zju_sample(seq, 1, (0, 1, 2), config)
    check_sample(sample)
    assert sample.joints_3d_valid.sum() == 24 and not sample.joints_3d_valid[3]
    assert np.all(sample.bbox[0] < sample.joints_3d[sample.joints_3d_valid].min(0))
    for view in sample.views:
        assert not view.has_depth and not view.depth.any()
        uv, _ = view.camera().project(sample.joints_3d)
        vis = view.visible
        assert vis.sum() >= 15 and not vis[3]
        assert np.abs(uv[vis] - view.joints_2d[vis]).max() < 0.5
        # The mask covers the projected torso joints (mid-hip, neck) where visible.
        for j in (1, 8):
            if vis[j]:
                u, v = np.round(view.joints_2d[j]).astype(int)
                assert view.mask[max(v - 2, 0):v + 3, max(u - 2, 0):u + 3].any()
    # The 2D-keypoint path (undistort, ROI transform) agrees with the projected 3D joints.
    from_2d = zju_sample(seq, 1, (0, 1, 2), ZjuConfig(resolution=RES, view_sets=((0, 1, 2),), joints_2d_from="kpts2d"))
    for a, b in zip(sample.views, from_2d.views):
        both = a.visible & b.visible
        assert both.sum() >= 5
        assert np.abs(a.joints_2d[both] - b.joints_2d[both]).max() < 0.05
        assert np.array_equal(a.image, b.image)


def test_triangulates_when_there_are_no_3d_joints(tmp_path, subject):
    _, cams, frames = subject
    f = frames[1]
    root = write_zju_format(tmp_path / "no3d", cams, [ZjuFrame(f.images, f.masks, f.kpts2d, None)], image_ext=".png")
    sample = zju_sample(ZjuSequence(root), 0, (0, 1), ZjuConfig(resolution=RES, view_sets=((0, 1),)))
    assert sample.metadata["joints_3d_source"] == "triangulated"
    valid = sample.joints_3d_valid
    assert valid.sum() >= 15
    err = np.linalg.norm(sample.joints_3d[valid] - f.joints_3d[valid, :3], axis=-1)
    assert np.median(err) < 0.02


def test_convert_then_load_as_tensors(tmp_path, subject):
    root, _, _ = subject
    out = tmp_path / "ds"
    n = convert_zju(root, out, ZjuConfig(resolution=RES, view_sets=((0, 1, 2), (2, 3, 0))), split="train_sim",
                    shard_size=3)
    assert n == 4
    data = ShardedSplit(out, "train_sim")
    assert [m["cameras"] for m in data.all_metadata()] == [[0, 1, 2], [2, 3, 0]] * 2
    torch = pytest.importorskip("torch")
    from training.data.torch_dataset import MultiViewDataset

    item = MultiViewDataset(out, "train_sim")[3]
    assert item["tgt_images"].shape == (3, 3, RES, RES) and item["tgt_images"].dtype == torch.float32
    assert not bool(item["tgt_has_depth"].any())


# ------------------------------------------------------------------ errors
def test_missing_annots_names_the_file(tmp_path):
    with pytest.raises(DatasetError, match="annots.npy") as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


def test_malformed_annots_names_the_file(tmp_path):
    np.save(tmp_path / ANNOTS, {"cams": {"K": [np.eye(3)]}, "ims": []}, allow_pickle=True)
    with pytest.raises(DatasetError, match="K, R, T and D") as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


@pytest.mark.parametrize("keep", [130, 200, 371])
def test_truncated_annots_names_the_file(tmp_path, subject, keep):
    data = (subject[0] / ANNOTS).read_bytes()
    (tmp_path / ANNOTS).write_bytes(data[:keep])
    with pytest.raises(DatasetError, match="unreadable annots") as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


def test_missing_image_and_mask_name_the_file(tmp_path, subject):
    _, cams, frames = subject
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(frames[0].images[:2], frames[0].masks[:2])],
                            image_ext=".png")
    seq = ZjuSequence(root)
    (root / "Camera_B2" / "000000.png").unlink()
    with pytest.raises(DatasetError, match="image") as err:
        seq.read_image(0, 1)
    assert err.value.path == str(root / "Camera_B2" / "000000.png")
    (root / "mask" / "Camera_B1" / "000000.png").unlink()
    with pytest.raises(DatasetError, match="mask") as err:
        seq.read_mask(0, 0)
    assert err.value.path == str(root / "mask" / "Camera_B1" / "000000.png")


def test_an_image_or_mask_of_a_compression_opencv_does_not_decode_names_it(tmp_path, subject):
    # a JPEG 2000 TIFF copy was "missing or unreadable", as a corrupt file is (and read as a black frame before
    # session 64): the error names its compression, as ghnerf-run's and ghcal's do
    import cv2

    from tests.odd_images import tiff_laid_out

    _, cams, frames = subject
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(frames[0].images[:2], frames[0].masks[:2])],
                            image_ext=".png")
    seq = ZjuSequence(root)
    for path in (root / "Camera_B2" / "000000.png", root / "mask" / "Camera_B1" / "000000.png"):
        data = cv2.imencode(".tiff", cv2.imread(str(path)), [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
        path.write_bytes(tiff_laid_out(data, changed={259: (3, (34712,))}))  # a TIFF's bytes, its name kept
    with pytest.raises(DatasetError, match=r"cannot read the image: it is a TIFF of Compression 34712 \(JPEG 2000\)"):
        seq.read_image(0, 1)
    with pytest.raises(DatasetError, match=r"cannot read the mask: it is a TIFF of Compression 34712 \(JPEG 2000\)"):
        seq.read_mask(0, 0)


def test_config_errors_name_the_field():
    with pytest.raises(DataConfigError, match="ZjuConfig.view_sets"):
        ZjuConfig(view_sets=((0,),))
    with pytest.raises(DataConfigError, match="ZjuConfig.joints_2d_from"):
        ZjuConfig(joints_2d_from="smpl")
    with pytest.raises(DataConfigError, match="ZjuConfig.resolution"):
        ZjuConfig(resolution=100)


@pytest.mark.parametrize("mutate, where", [
    (lambda a: a["cams"].update(K=5), "cams.K must be a list"),
    (lambda a: a["cams"]["K"].__setitem__(0, [["a"] * 3] * 3), r"cams.K\[0\]: not a numeric array"),
    (lambda a: a["cams"]["R"].__setitem__(1, {"r": 1}), r"cams.R\[1\]: not a numeric array"),
    (lambda a: a["ims"][0].update(ims="abcd"), r"ims\[0\] must be a dict whose 'ims' lists 4 image paths"),
    (lambda a: a["ims"][1].update(ims=[1, 2, 3, 4]), r"ims\[1\] must be a dict"),
    (lambda a: a["ims"].__setitem__(0, "Camera_B1"), r"ims\[0\] must be a dict"),
])
def test_malformed_annots_fields_name_the_file_and_field(tmp_path, subject, mutate, where):
    annots = np.load(subject[0] / ANNOTS, allow_pickle=True).item()
    annots["cams"] = {k: list(v) for k, v in annots["cams"].items()}
    mutate(annots)
    np.save(tmp_path / ANNOTS, annots, allow_pickle=True)
    with pytest.raises(DatasetError, match=where) as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


def test_malformed_keypoint_entries_name_the_file(tmp_path, subject):
    import shutil

    root = tmp_path / "s"
    shutil.copytree(subject[0], root)
    annots = np.load(root / ANNOTS, allow_pickle=True).item()
    annots["ims"][0]["kpts2d"] = [["x"] * 3] * 25
    np.save(root / ANNOTS, annots, allow_pickle=True)
    with pytest.raises(DatasetError, match=r"ims\[0\]\['kpts2d'\]: not a numeric array"):
        ZjuSequence(root).keypoints2d(0)
    (root / "keypoints3d" / "000001.json").write_text(json.dumps([[1, 2, 3]]))
    with pytest.raises(DatasetError, match="person 0 must be") as err:
        ZjuSequence(root).joints_3d(1)
    assert err.value.path == str(root / "keypoints3d" / "000001.json")
    (root / "keypoints3d" / "000001.json").write_text(json.dumps([{"keypoints3d": [["x"] * 4] * 25}]))
    with pytest.raises(DatasetError, match="keypoints3d: not a numeric array"):
        ZjuSequence(root).joints_3d(1)
    bad_2d = root / "kp.json"
    for data, match in (({"people": [7]}, "'people' must be a list"), ([7], "person 0 must be"),
                        ({"annots": [{"keypoints": "abc"}]}, "not a numeric array")):
        from training.data.zju import parse_keypoints2d_json

        with pytest.raises(DatasetError, match=match):
            parse_keypoints2d_json(data, bad_2d)


def test_keypoints_of_another_skeleton_are_refused_by_their_joint_count(tmp_path, subject):
    # more than 25 joints were cut to their first 25 without a word: Halpe's 26 (COCO's order first) or an OpenPose
    # BODY_135 file read as BODY_25; EasyMocap's bodyhand (67) and bodyhandface (137) begin with BODY_25's joints
    import shutil

    from training.data.zju import parse_keypoints2d_json

    root = tmp_path / "s"
    shutil.copytree(subject[0], root)
    path = root / "keypoints3d" / "000001.json"
    body = json.loads(path.read_text())[0]["keypoints3d"]
    path.write_text(json.dumps([{"id": 0, "keypoints3d": body + [[0.0, 0.0, 0.0, 1.0]]}]))
    with pytest.raises(DatasetError, match=r"keypoints3d must be \(25, 4\) BODY_25 .* got \(26, 4\)") as err:
        ZjuSequence(root).joints_3d(1)
    assert err.value.path == str(path)
    path.write_text(json.dumps([{"id": 0, "keypoints3d": body + [[0.0, 0.0, 0.0, 1.0]] * 42}]))
    np.testing.assert_array_equal(ZjuSequence(root).joints_3d(1), np.asarray(body))  # bodyhand: its body
    kp = subject[2][0].kpts2d[0]
    with pytest.raises(DatasetError, match="pose_keypoints_2d has 405 values, expected 75"):
        parse_keypoints2d_json({"people": [{"pose_keypoints_2d": np.tile(kp, (6, 1))[:135].ravel().tolist()}]},
                               root / "kp.json")
    with pytest.raises(DatasetError, match=r"keypoints must be \(25, 3\) BODY_25 .* got \(26, 3\)"):
        parse_keypoints2d_json({"annots": [{"keypoints": np.vstack([kp, kp[:1]]).tolist()}]}, root / "kp.json")
    np.testing.assert_array_equal(parse_keypoints2d_json({"annots": [{"keypoints": kp.tolist()}]}, root / "kp.json"),
                                  kp)


def test_frames_that_select_no_frame_are_refused_and_the_split_kept(tmp_path, subject):
    # a --frames range past the subject's end (a copy of fewer frames than thought) converted 0 samples, exit 0,
    # and replaced the converted split with an empty one
    out = tmp_path / "d"
    convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 1),)), split="s")
    before = {p.name: p.read_bytes() for p in (out / "s").rglob("*") if p.is_file()}
    for frames in ((100, 200, 1), (2, -1, 1), (1, 1, 1)):
        with pytest.raises(DataConfigError, match=r"ZjuConfig.frames: selects none of the 2 frames in .* \(0 to 1\), "
                                                  r"got " + re.escape(str(frames))):
            convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 1),), frames=frames), split="s")
    assert len(ShardedSplit(out, "s")) == 2
    assert {p.name: p.read_bytes() for p in (out / "s").rglob("*") if p.is_file()} == before


def test_a_split_of_another_view_count_names_both_layouts(tmp_path, subject):
    # was "holds a dataset of another resolution or view count", naming neither
    out = tmp_path / "d"
    convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 1),)), split="two")
    with pytest.raises(DatasetError, match=r"holds 64 px scenes of 2 views \(resolution, view_names\); this "
                                           r"conversion makes 64 px scenes of 4 views \(--res, --view-set\)") as err:
        convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 3, 1, 2),)), split="four")
    assert err.value.path == str(out / "dataset.json")
    assert sorted(ShardedSplit(out, "two").manifest["splits"]) == ["two"]


def test_a_failed_reconversion_leaves_the_previous_split_whole(tmp_path, subject):
    import shutil

    root = tmp_path / "s"
    shutil.copytree(subject[0], root)
    out = tmp_path / "ds"
    first = ZjuConfig(resolution=RES, view_sets=((0, 1),), margin_frac=0.25)
    assert convert_zju(root, out, first, split="s", shard_size=1) == 2
    before = [ShardedSplit(out, "s").arrays(i)["roi"].tolist() for i in range(2)]
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["splits"]["s"]["source_config"]["zju"]["margin_frac"] == 0.25

    # frame 1 lacks a mask: the new settings fail after frame 0's shard was written
    (root / "mask" / "Camera_B2" / "000001.png").unlink()
    second = ZjuConfig(resolution=RES, view_sets=((0, 1),), margin_frac=1.0)
    with pytest.raises(DatasetError, match="mask"):
        convert_zju(root, out, second, split="s", shard_size=1)
    split = ShardedSplit(out, "s")
    assert [split.arrays(i)["roi"].tolist() for i in range(2)] == before  # not one shard of each
    assert json.loads((out / "dataset.json").read_text()) == manifest
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json", "dataset.lock", "s"]  # no temporary left

    # a conversion that succeeds replaces the split and records its settings
    shutil.copy(subject[0] / "mask" / "Camera_B2" / "000001.png", root / "mask" / "Camera_B2" / "000001.png")
    assert convert_zju(root, out, second, split="s", shard_size=2) == 2
    split = ShardedSplit(out, "s")
    assert [split.arrays(i)["roi"].tolist() for i in range(2)] != before
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["splits"]["s"]["source_config"]["zju"]["margin_frac"] == 1.0
    assert manifest["source_config"]["zju"]["margin_frac"] == 1.0
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json", "dataset.lock", "s"]
    assert sorted(p.name for p in (out / "s").iterdir()) == ["shard_000000"]  # the old 1-sample shards are gone


def test_a_conversion_into_a_folder_another_process_writes_is_refused(tmp_path, subject):
    import subprocess
    import sys

    from training.data.cache import WRITER_LOCK

    out = tmp_path / "ds"
    out.mkdir()
    # another process holds the folder's writer lock (a generate or a conversion of another split)
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, sys, time; f = open(sys.argv[1], 'a'); "
                               "fcntl.flock(f, fcntl.LOCK_EX); print('held', flush=True); time.sleep(60)",
                               str(out / WRITER_LOCK)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(DatasetError, match="dataset.lock: another process holds this lock"):
            convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 1),)), split="s", shard_size=1)
        assert sorted(p.name for p in out.iterdir()) == [WRITER_LOCK]  # nothing read or written
    finally:
        holder.kill()
        holder.wait()
    assert convert_zju(subject[0], out, ZjuConfig(resolution=RES, view_sets=((0, 1),)), split="s", shard_size=1) == 2


@pytest.mark.parametrize("shard_size", [0, -1, 100_001, 2.0, True])
def test_convert_refuses_a_bad_shard_size(tmp_path, subject, shard_size):
    with pytest.raises(DataConfigError, match="shard_size"):
        convert_zju(subject[0], tmp_path / "ds", ZjuConfig(resolution=RES, view_sets=((0, 1),)), shard_size=shard_size)
    assert not (tmp_path / "ds" / "dataset.json").exists()


def test_a_copy_with_t_in_metres_is_refused(tmp_path, subject):
    # read as millimetres, every camera sat within millimetres of the origin and the samples were wrong, silently
    annots = np.load(subject[0] / ANNOTS, allow_pickle=True).item()
    annots["cams"] = {k: list(v) for k, v in annots["cams"].items()}
    annots["cams"]["T"] = [np.asarray(t) / 1000.0 for t in annots["cams"]["T"]]
    np.save(tmp_path / ANNOTS, annots, allow_pickle=True)
    with pytest.raises(DatasetError, match=r"cams.T: the 4 camera centres lie within .* mm .* in metres") as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


@pytest.mark.parametrize("eyes", [
    [(-0.0375, 0.0, 0.0), (0.0375, 0.0, 0.0)],  # the example rig's 7.5 cm pair
    [(0.0, 0.0, 0.0), (0.008, 0.008, 0.0)],  # 11 mm on a diagonal: under 10 mm along either axis
])
def test_a_short_baseline_rig_written_in_millimetres_reads_back(tmp_path, subject, eyes):
    # the wrong-unit check refused every rig under 10 cm (per axis), so write_zju_format's own output of a stereo
    # pair a few centimetres apart could not be read; only a rig no usable calibration has is taken for metres now
    _, _, frames = subject
    f = frames[0]
    cams = []
    for name, eye in zip(("left", "right"), eyes):
        R, t = look_at(np.array(eye), np.array([0.0, -0.9, 3.0]))
        cams.append(Camera(name, SIZE, SIZE, intrinsics_from_fov(SIZE, SIZE, 62.0), np.zeros(5), R, t))
    root = write_zju_format(tmp_path / "pair", cams, [ZjuFrame(f.images[:2], f.masks[:2])], image_ext=".png")
    seq = ZjuSequence(root)
    assert np.allclose(seq.camera(1).t, cams[1].t, rtol=0, atol=1e-12)
    # the same pair in metres, read as millimetres, is 0.075 mm (0.011 mm) wide: still refused
    annots = np.load(root / ANNOTS, allow_pickle=True).item()
    annots["cams"]["T"] = [np.asarray(t) / 1000.0 for t in annots["cams"]["T"]]
    np.save(root / ANNOTS, annots, allow_pickle=True)
    with pytest.raises(DatasetError, match=r"cams.T: the 2 camera centres lie within 0\.\d+ mm"):
        ZjuSequence(root)


def test_masks_and_sizes_are_read_as_a_partial_copy_needs(tmp_path, subject):
    import cv2

    _, cams, frames = subject
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(f.images[:2], f.masks[:2], f.kpts2d[:2], f.joints_3d)
                                                        for f in frames[:2]],
                            image_ext=".png")
    # an RGBA mask (re-saved by an editor): its opaque alpha made every pixel the person
    mask_path = root / "mask" / "Camera_B1" / "000001.png"
    grey = cv2.imread(str(mask_path), cv2.IMREAD_UNCHANGED)
    rgba = np.dstack([grey, grey, grey, np.full_like(grey, 255)])
    cv2.imwrite(str(mask_path), rgba)
    seq = ZjuSequence(root)
    assert np.array_equal(seq.read_mask(1, 0), grey != 0) and not seq.read_mask(1, 0).all()
    # a camera's size from the frame asked for: without its frame 0 the other frames still have a camera
    (root / "Camera_B2" / "000000.png").unlink()
    assert seq.camera(1, frame=1).size == (cams[1].width, cams[1].height)
    # a mask of another size than its image is named, not the image
    small = root / "mask" / "Camera_B2" / "000001.png"
    cv2.imwrite(str(small), np.zeros((10, 10), np.uint8))
    with pytest.raises(DatasetError, match=r"mask \(10, 10\) differs from its image") as err:
        zju_sample(seq, 1, (0, 1), ZjuConfig(resolution=64, view_sets=((0, 1),)))
    assert err.value.path == str(small)


def test_a_cut_cache_array_is_named_and_rendered_again(tmp_path):
    from training.data.cache import _array_is_whole

    path = tmp_path / "images.npy"
    np.save(path, np.zeros((4, 8), np.float32))
    assert _array_is_whole(path)
    path.write_bytes(path.read_bytes()[:60])
    assert not _array_is_whole(path)
    path.write_bytes(b"")  # a stop mid-write: np.load raised a bare EOFError
    assert not _array_is_whole(path)


def test_triangulating_reads_no_image_of_a_camera_the_view_set_does_not_use(tmp_path, subject):
    # the joints of a frame without keypoints3d are triangulated from every camera's keypoints: each camera's
    # image size was read from one of its images, so a copy without cameras 2 and 3's images failed for (0, 1)
    _, cams, frames = subject
    f = frames[1]
    root = write_zju_format(tmp_path / "no3d", cams, [ZjuFrame(f.images, f.masks, f.kpts2d, None)], image_ext=".png")
    for c in (3, 4):
        (root / f"Camera_B{c}" / "000000.png").unlink()
    config = ZjuConfig(resolution=RES, view_sets=((0, 1),))
    sample = zju_sample(ZjuSequence(root), 0, (0, 1), config)
    assert sample.metadata["joints_3d_source"] == "triangulated"
    valid = sample.joints_3d_valid
    assert valid.sum() >= 15
    assert np.median(np.linalg.norm(sample.joints_3d[valid] - f.joints_3d[valid, :3], axis=-1)) < 0.02
    # a used camera's missing image is still named
    (root / "Camera_B2" / "000000.png").unlink()
    with pytest.raises(DatasetError, match="missing or unreadable image") as err:
        zju_sample(ZjuSequence(root), 0, (0, 1), config)
    assert err.value.path == str(root / "Camera_B2" / "000000.png")


@pytest.mark.parametrize("field, value, says", [
    ("D", np.zeros((3, 1)), r"cams.D\[2\] must hold 0, 4, 5, 8, 12 or 14 OpenCV distortion coefficients, got "
                            r"shape \(3, 1\)"),
    ("D", np.zeros((5, 2)), r"cams.D\[2\] must hold .* got shape \(5, 2\)"),
    ("K", np.eye(4), r"cams.K\[2\] must be a 3x3 intrinsic matrix, got shape \(4, 4\)"),
    ("T", np.zeros((2, 1)), r"cams.T\[2\] must be a 3-vector .* got shape \(2, 1\)"),
    ("R", np.eye(2), r"cams.R\[2\] must be a 3x3 rotation or a Rodrigues 3-vector, got shape \(2, 2\)"),
])
def test_every_cameras_calibration_shapes_are_checked_when_annots_are_opened(tmp_path, subject, field, value, says):
    # a D of another length was refused only when its camera made its first sample, and named "camera 2", not
    # the field: a conversion of other view sets went through, and one using it failed midway
    annots = np.load(subject[0] / ANNOTS, allow_pickle=True).item()
    annots["cams"] = {k: list(v) for k, v in annots["cams"].items()}
    annots["cams"][field][2] = value
    np.save(tmp_path / ANNOTS, annots, allow_pickle=True)
    with pytest.raises(DatasetError, match=says) as err:
        ZjuSequence(tmp_path)
    assert err.value.path == str(tmp_path / ANNOTS)


def _copy_without_masks(tmp_path, subject, missing):
    import shutil

    root = tmp_path / "s"
    shutil.copytree(subject[0], root)
    shutil.copytree(root / "mask", root / "mask_cihp")
    for path in missing:
        (root / path).unlink()
    return root


def test_a_missing_mask_stops_the_conversion_unless_skipped_and_counted(tmp_path, subject, caplog):
    import logging

    root = _copy_without_masks(tmp_path, subject, ["mask/Camera_B2/000001.png"])
    out = tmp_path / "ds"
    strict = ZjuConfig(resolution=RES, view_sets=((0, 1), (2, 3)))
    with pytest.raises(DatasetError, match="missing or unreadable mask") as err:
        convert_zju(root, out, strict, split="s", shard_size=2)
    assert err.value.path == str(root / "mask" / "Camera_B2" / "000001.png")

    skip = ZjuConfig(resolution=RES, view_sets=((0, 1), (2, 3)), skip_missing_masks=True)
    with caplog.at_level(logging.WARNING, logger="training.data.zju_samples"):
        assert convert_zju(root, out, skip, split="s", shard_size=2) == 3  # frame 1 of (0, 1) left out, (2, 3) kept
    assert "s: 1 of 4 samples skipped for a missing mask (frames 1; first missing: " in caplog.text
    assert str(root / "mask" / "Camera_B2" / "000001.png") in caplog.text
    split = ShardedSplit(out, "s")
    assert [(m["frame"], m["cameras"]) for m in split.all_metadata()] == [(0, [0, 1]), (0, [2, 3]), (1, [2, 3])]
    assert json.loads((out / "dataset.json").read_text())["splits"]["s"]["skipped_missing_masks"] == 1

    # with every mask missing the conversion is refused (a wrong mask_dir, more likely than a sparse copy)
    for path in (root / "mask_cihp").rglob("*.png"):
        path.unlink()
    with pytest.raises(DatasetError, match="every one of the 4 samples lacks one"):
        convert_zju(root, out, ZjuConfig(resolution=RES, view_sets=((0, 1), (2, 3)), mask_dir="mask_cihp",
                                         skip_missing_masks=True), split="t", shard_size=2)
    assert "t" not in json.loads((out / "dataset.json").read_text())["splits"]


def test_a_missing_mask_falls_back_to_the_other_mask_folder_on_request(tmp_path, subject):
    root = _copy_without_masks(tmp_path, subject, ["mask/Camera_B2/000001.png", "mask_cihp/Camera_B1/000000.png"])
    seq = ZjuSequence(root, mask_fallback=True)
    assert seq.mask_path(1, 1) == root / "mask_cihp" / "Camera_B2" / "000001.png"
    assert seq.mask_path(0, 0) == root / "mask" / "Camera_B1" / "000000.png"
    assert np.array_equal(seq.read_mask(1, 1), subject[2][1].masks[1])
    assert ZjuSequence(root, mask_dir="mask_cihp", mask_fallback=True).mask_path(0, 0) == \
        root / "mask" / "Camera_B1" / "000000.png"
    out = tmp_path / "ds"
    config = ZjuConfig(resolution=RES, view_sets=((0, 1),), mask_fallback=True)
    assert convert_zju(root, out, config, split="s", shard_size=2) == 2
    masks = [m["masks"] for m in ShardedSplit(out, "s").all_metadata()]
    assert masks == [["mask/Camera_B1/000000.png", "mask/Camera_B2/000000.png"],
                     ["mask/Camera_B1/000001.png", "mask_cihp/Camera_B2/000001.png"]]
    # missing from both: named under mask_dir
    (root / "mask_cihp" / "Camera_B2" / "000001.png").unlink()
    with pytest.raises(DatasetError, match="missing or unreadable mask") as err:
        ZjuSequence(root, mask_fallback=True).read_mask(1, 1)
    assert err.value.path == str(root / "mask" / "Camera_B2" / "000001.png")
    with pytest.raises(DataConfigError, match="ZjuConfig.mask_fallback"):
        ZjuConfig(mask_fallback="yes")


# ------------------------------------------------------------------ the command line
def test_the_convert_command_converts_a_subject_into_a_split(tmp_path, subject, caplog):
    """Review 52: ZJU-MoCap had no command, only convert_zju to call from Python."""
    import logging

    from training.data.convert_zju import main

    out = tmp_path / "ds"
    with caplog.at_level(logging.INFO):
        assert main([str(subject[0]), "--out", str(out), "--split", "train_sim", "--res", str(RES),
                     "--view-set", "0,1,2", "--view-set", "2,3,0", "--frames", "0:-1:1", "--shard-size", "3"]) == 0
    split = ShardedSplit(out, "train_sim")
    assert [m["cameras"] for m in split.all_metadata()] == [[0, 1, 2], [2, 3, 0]] * 2
    assert split.resolution == RES
    entry = json.loads((out / "dataset.json").read_text())["splits"]["train_sim"]
    assert entry["source_config"]["zju"]["view_sets"] == [[0, 1, 2], [2, 3, 0]] and entry["shard_size"] == 3
    assert "4 samples converted into split 'train_sim'" in caplog.text
    assert main([str(subject[0]), "--out", str(out), "--split", "one", "--res", str(RES), "--view-set", "1,2,3",
                 "--frames", "1"]) == 0  # from frame 1 on, into the same dataset (of 3 views)
    assert [(m["frame"], m["cameras"]) for m in ShardedSplit(out, "one").all_metadata()] == [(1, [1, 2, 3])]
    assert len(ShardedSplit(out, "train_sim")) == 4  # the other split stays


def test_the_convert_command_has_help(capsys):
    from training.data.convert_zju import main

    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    said = capsys.readouterr().out
    assert "python -m training.data.convert_zju" in said and "--view-set" in said and "annots.npy" in said
    with pytest.raises(SystemExit) as bad:
        main(["somewhere", "--out", "ds", "--view-set", "0,x"])
    assert bad.value.code == 2 and "camera indices separated by commas" in capsys.readouterr().err


def _convert_fails(caplog, *argv) -> str:
    import logging

    from training.data.convert_zju import main

    caplog.clear()
    with caplog.at_level(logging.ERROR):
        assert main([str(a) for a in argv]) == 2
    return caplog.text


def test_the_convert_command_names_a_missing_file_or_folder(tmp_path, subject, caplog):
    import shutil

    out = tmp_path / "ds"
    args = ("--out", out, "--res", RES, "--view-set", "0,1")
    said = _convert_fails(caplog, tmp_path / "nowhere", *args)
    assert f"{tmp_path / 'nowhere'}: missing: no such subject folder" in said
    (tmp_path / "empty").mkdir()
    said = _convert_fails(caplog, tmp_path / "empty", *args)
    assert f"{tmp_path / 'empty' / ANNOTS}: missing: not a ZJU-MoCap subject folder" in said

    root = tmp_path / "s"
    shutil.copytree(subject[0], root)
    shutil.rmtree(root / "Camera_B2")  # a copy unpacked without one camera
    said = _convert_fails(caplog, root, *args)
    assert f"{root / 'Camera_B2'}: missing: the images folder of camera 1 (annots.npy's ims[0] names " \
           "Camera_B2/000000.png)" in said
    said = _convert_fails(caplog, root, *args[:-1], "2,3", "--mask-dir", "mask_cihp")  # camera 1 not used: its masks
    assert f"{root / 'mask_cihp'}: missing: the mask folder (mask_dir='mask_cihp'); this copy has mask/: choose it " \
           "with mask_dir='mask'" in said
    shutil.rmtree(root / "mask")
    said = _convert_fails(caplog, root, *args[:-1], "2,3")
    assert f"{root / 'mask'}: missing: the mask folder (mask_dir='mask') (nor mask_cihp/)" in said
    said = _convert_fails(caplog, root, *args[:-1], "0,9")
    assert "ZjuConfig.view_sets: camera 9 does not exist (4 cameras in" in said
    assert not (out / "dataset.json").exists()  # nothing converted


@pytest.mark.parametrize("orientation", [3, 6])
def test_an_image_tagged_to_be_turned_is_read_as_stored_as_its_mask_and_calibration_are(tmp_path, subject,
                                                                                          orientation):
    # OpenCV turned it by its EXIF orientation for IMREAD_COLOR while its mask (IMREAD_UNCHANGED) and annots' K
    # stayed on the stored pixel grid: half a turn (3) kept the size, the person upside down against both
    import cv2

    from tests.exif_images import jpeg_turned

    _, cams, frames = subject
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(f.images[:2], f.masks[:2], f.kpts2d[:2], f.joints_3d)
                                                        for f in frames[:1]])
    seq = ZjuSequence(root)
    path = seq.image_path(0, 0)
    stored = cv2.imread(str(path), cv2.IMREAD_COLOR)
    path.write_bytes(jpeg_turned(path.read_bytes(), orientation))
    assert not np.array_equal(cv2.imread(str(path), cv2.IMREAD_COLOR), stored)  # OpenCV does turn it by default
    assert np.array_equal(seq.read_image(0, 0), stored)


def test_an_image_or_mask_whose_header_is_beyond_opencv_s_size_limits_is_named(tmp_path, subject):
    # cv2.imread raises for it rather than failing: a conversion stopped with a cv2.error naming no file
    from tests.odd_images import bmp_beyond_opencv_s_limits

    _, cams, frames = subject
    root = write_zju_format(tmp_path / "s", cams[:2], [ZjuFrame(frames[0].images[:2], frames[0].masks[:2])],
                            image_ext=".png")
    seq = ZjuSequence(root)
    for path, read in ((seq.image_path(0, 0), seq.read_image), (seq.mask_path(0, 0), seq.read_mask)):
        path.write_bytes(bmp_beyond_opencv_s_limits())
        with pytest.raises(DatasetError, match="unreadable") as err:
            read(0, 0)
        assert err.value.path == str(path)


def _stop_between_the_renames(monkeypatch, out, split, signum):
    """Send ``signum`` to this process right after the conversion renames the old split away (the first of its
    two renames), where a stop used to leave no split at all."""
    import os
    import signal
    import time

    real_replace = os.replace

    def replace(src, dst):
        real_replace(src, dst)
        if str(src) == str(out / split) and ".old-" in str(dst):
            os.kill(os.getpid(), signum)
            time.sleep(0.05)  # (a handler that raises does so here, between the renames)

    monkeypatch.setattr(os, "replace", replace)
    return signal


@pytest.mark.parametrize("signum_name,status,words", [("SIGINT", 130, "Ctrl-C"), ("SIGTERM", 143, "SIGTERM")])
def test_a_stop_between_the_two_renames_of_the_swap_loses_no_split_and_is_said_truly(
        tmp_path, subject, caplog, monkeypatch, signum_name, status, words):
    """Review 63: a Ctrl-C (or SIGTERM) landing between the swap's two renames left no split; the next run deleted
    the old one as a leftover, while the message said the split was as it was."""
    import logging
    import signal

    from training.data.convert_zju import main

    out = tmp_path / "ds"
    argv = [str(subject[0]), "--out", str(out), "--split", "s", "--res", str(RES), "--view-set", "0,1",
            "--shard-size", "1"]
    assert main(argv) == 0
    _stop_between_the_renames(monkeypatch, out, "s", getattr(signal, signum_name))
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        assert main([*argv, "--margin", "1.0"]) == status
    assert f"stopped by {words} once the conversion was done: split 's' of {out} is the new one" in caplog.text
    monkeypatch.undo()
    split = ShardedSplit(out, "s")  # whole, with its entry: the new one, as said
    assert len(split) == 2
    entry = json.loads((out / "dataset.json").read_text())["splits"]["s"]
    assert entry["source_config"]["zju"]["margin_frac"] == 1.0
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json", "dataset.lock", "s"]


class _Killed(BaseException):
    """A kill (SIGKILL, a power cut) at one point of the swap: nothing after it runs, no handler, no clean-up."""


def _kill_the_conversion_at(monkeypatch, out, point):
    """Make the conversion stop dead at ``point`` of its swap: right after the manifest without the split's entry
    is written, after the old split is renamed away, or after the new one is renamed in."""
    import os
    from pathlib import Path

    from training.data import zju_samples

    real_replace, real_write = os.replace, zju_samples.write_manifest

    def replace(src, dst):
        real_replace(src, dst)
        if (point == "between the renames" and Path(src) == out / "s") or (
                point == "after both renames" and Path(dst) == out / "s"):
            raise _Killed

    def write_manifest(root, manifest):
        real_write(root, manifest)
        if point == "after the entry was set aside":
            raise _Killed

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(zju_samples, "write_manifest", write_manifest)


@pytest.mark.parametrize("point", ["after the entry was set aside", "between the renames", "after both renames"])
def test_a_split_half_swapped_by_a_killed_conversion_is_put_back_not_deleted(tmp_path, subject, caplog, monkeypatch,
                                                                             point):
    """A conversion killed outright during its swap (SIGKILL, a power cut: nothing can hold those) left the split's
    entry out of the manifest, and between the two renames the old shards as ``<split>.old-<pid>`` alone, which
    the next run deleted as a leftover. The next run puts the split back as it was before the killed one, shards and
    entry, so that a failure of its own leaves it so."""
    import logging
    import shutil

    root = tmp_path / "subject"
    shutil.copytree(subject[0], root)
    out = tmp_path / "ds"
    config = ZjuConfig(resolution=RES, view_sets=((0, 1),))
    assert convert_zju(root, out, config, split="s", shard_size=1) == 2
    before = [ShardedSplit(out, "s").arrays(i)["roi"].tolist() for i in range(2)]
    manifest = json.loads((out / "dataset.json").read_text())

    _kill_the_conversion_at(monkeypatch, out, point)
    with pytest.raises(_Killed):
        convert_zju(root, out, ZjuConfig(resolution=RES, view_sets=((0, 1),), margin_frac=1.0), split="s",
                    shard_size=2)
    monkeypatch.undo()
    assert "s" not in json.loads((out / "dataset.json").read_text())["splits"]  # the state the kill left

    (root / "mask" / "Camera_B2" / "000001.png").unlink()  # this conversion fails after its first shard
    with caplog.at_level(logging.WARNING), pytest.raises(DatasetError, match="mask"):
        convert_zju(root, out, config, split="s", shard_size=1)
    assert json.loads((out / "dataset.json").read_text()) == manifest
    assert [ShardedSplit(out, "s").arrays(i)["roi"].tolist() for i in range(2)] == before
    assert sorted(p.name for p in out.iterdir()) == ["dataset.json", "dataset.lock", "s"]
    assert "left half-swapped by a conversion killed during its swap: the split before it put back" in caplog.text


def test_an_entry_whose_shards_were_gone_is_not_put_back_with_a_killed_conversions_shards(tmp_path, subject,
                                                                                           monkeypatch):
    """A split in the manifest whose folder was deleted had its entry kept aside all the same: a conversion killed
    after renaming its new shards in left them there with no old ones, and the next run put the old entry back
    with the new shards (shard_size 1 over shards of 2), the pairing the swap exists to prevent."""
    import shutil

    root = tmp_path / "subject"
    shutil.copytree(subject[0], root)
    out = tmp_path / "ds"
    config = ZjuConfig(resolution=RES, view_sets=((0, 1),))
    assert convert_zju(root, out, config, split="s", shard_size=1) == 2
    shutil.rmtree(out / "s")  # the shards deleted by hand, the entry left

    _kill_the_conversion_at(monkeypatch, out, "after both renames")
    with pytest.raises(_Killed):
        convert_zju(root, out, config, split="s", shard_size=2)
    monkeypatch.undo()

    (root / "mask" / "Camera_B2" / "000001.png").unlink()  # the next conversion fails before its swap
    with pytest.raises(DatasetError, match="mask"):
        convert_zju(root, out, config, split="s", shard_size=1)
    assert "s" not in json.loads((out / "dataset.json").read_text())["splits"]
