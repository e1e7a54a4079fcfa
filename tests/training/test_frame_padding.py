"""Training crops that reach past the camera's frame show the runtime's black padding (TargetConfig.frame_padding)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from drivers.sim import RigPlacement, random_scene
from ghnerf_runtime.config import RoiConfig
from ghnerf_runtime.preprocess import Roi, apply_crop_maps, build_undistort_crop_maps
from training.data.errors import DataConfigError
from training.data.frame_padding import frame_coverage
from training.data.sample import Sample, sample_to_arrays
from training.data.targets import FRAME_KEY, TargetConfig, model_inputs
from training.data.views import render_view

S = 64


@pytest.fixture(scope="module")
def edge_crop():
    """A source crop whose box runs 25 % past the left edge of a simulated camera's frame: the training
    record and the runtime's crop of the same box from the rendered frame."""
    rig = RigPlacement().build()
    scene = random_scene(5, volume=rig.volume)
    cam, t = rig.cameras[0], 0.3
    joints = scene.joints_3d(t)
    roi = Roi(-58, 120, 240)  # 58 of its 240 columns lie left of the frame
    views = tuple(render_view(scene, c, roi, t, joints, resolution=S, supersample=2, roi_from_volume=False)
                  for c in (cam, rig.cameras[1]))
    record = sample_to_arrays(Sample(views, joints, np.ones(25, bool), np.stack(scene.bounding_box(t))))
    frame, _ = scene.render(cam, t, with_truth=False)
    maps = build_undistort_crop_maps(cam, roi, S, supersample=RoiConfig().supersample)  # the runtime's defaults
    runtime = cv2.cvtColor(apply_crop_maps(frame, maps), cv2.COLOR_BGR2RGB)
    return record, runtime, maps


def test_training_crop_at_the_edge_is_padded_as_the_runtime_pads_it(edge_crop):
    record, runtime, maps = edge_crop
    out = model_inputs(record, S, TargetConfig(heatmap_stride=0, frame_padding=True))
    train = np.rint(out["images"][0].transpose(1, 2, 0) * 255)
    padded = ~maps.inside  # the model pixels the runtime does not fill from the frame
    black = runtime.max(axis=-1) == 0
    assert 10 * S <= black.sum() <= padded.sum()  # the box crosses the edge: a band of black, ~a quarter
    # the pixels the runtime shows black are black in the training input, on the same side
    assert np.all(train[black] == 0)
    assert black[:, : S // 4 - 1].all() and not black[:, S // 4 + 1:].any()
    # the fade between them is the runtime's: the two crops differ there by a few levels at most
    band = padded & ~black
    assert band.any()
    assert np.abs(train[band] - runtime[band]).max() <= 12
    # inside the frame the training input is the stored crop, untouched
    inside = ~padded
    assert np.array_equal(train[inside], record["images"][0][inside].astype(float))
    # the rendering targets keep the whole picture (the room behind the band)
    assert out["tgt_images"][0, :, black].max() > 0.05


def test_padding_is_off_unless_asked_and_a_crop_inside_the_frame_is_unchanged(edge_crop):
    record = edge_crop[0]
    plain = model_inputs(record, S, TargetConfig(heatmap_stride=0))
    assert FRAME_KEY not in plain and plain["images"][0].max(axis=0)[:, :4].max() > 0.05
    assert frame_coverage(record["full_K"][1], record["full_size"][1], Roi(200, 100, 200), S) is None
    with pytest.raises(DataConfigError, match="frame_padding"):
        TargetConfig(frame_padding="yes")


def test_the_encoder_sees_every_view_padded():
    from training.pretrain_human import config_from_train_config, view_batch
    from training.train import TrainConfig

    images = torch.ones(3, 3, 8, 8)
    frame = torch.ones(3, 8, 8)
    frame[1, :, :2] = 0.0
    item = {"tgt_images": images, "tgt_heatmaps": torch.zeros(3, 25, 2, 2), FRAME_KEY: frame}
    seen, _ = view_batch([item], flip=False)
    assert seen[1, :, :, :2].abs().max() == 0 and seen[1, :, :, 2:].min() == 1 and seen[0].min() == 1
    # the pretraining stage follows the train config's switch unless its block says otherwise
    assert config_from_train_config({"frame_padding": True, "pretrain_human": {}}).frame_padding is True
    own = {"frame_padding": True, "pretrain_human": {"frame_padding": False}}
    assert not config_from_train_config(own).frame_padding
    assert TrainConfig().frame_padding is False


def test_edge_cut_shows_a_source_as_the_runtime_crops_a_person_at_the_frame_edge(edge_crop):
    from ghnerf_runtime.geometry import Camera

    record = dict(edge_crop[0])
    record["roi"] = np.array([[200, 100, 200]] * 2, np.int32)  # inside the 640x480 frame: no padding of its own
    config = TargetConfig(heatmap_stride=0, frame_padding=True, edge_cut=1.0)
    out = model_inputs(record, S, config, index=3)
    assert np.array_equal(out[FRAME_KEY], model_inputs(record, S, config, index=3)[FRAME_KEY])  # same every epoch
    assert not np.array_equal(out[FRAME_KEY][:2], model_inputs(record, S, config, index=4)[FRAME_KEY][:2])
    for i in range(2):
        black = out[FRAME_KEY][i] == 0
        cols = np.flatnonzero(black.all(axis=0))
        assert black.any(axis=0).sum() == len(cols) and 0.2 * S <= len(cols) <= 0.5 * S  # whole columns, one band
        assert cols[0] == 0 or cols[-1] == S - 1
        assert np.all(out["images"][i][:, black] == 0)
        # the runtime's crop of the same box from a camera whose frame starts (or ends) at the cut
        full = Camera("c", 640, 480, record["full_K"][i])
        first = 200 + round((cols[-1] + 1) * 200 / S) if cols[0] == 0 else 0
        last = 200 + round(cols[0] * 200 / S) if cols[0] != 0 else 640
        for c in range(first - 3, first + 4) if cols[0] == 0 else range(last - 3, last + 4):
            cut = full.cropped(c, 0, 640 - c, 480) if cols[0] == 0 else full.cropped(0, 0, c, 480)
            roi = Roi(200 - c, 100, 200) if cols[0] == 0 else Roi(200, 100, 200)
            maps = build_undistort_crop_maps(cut, roi, S, supersample=RoiConfig().supersample)
            if np.allclose(apply_crop_maps(np.ones((480, cut.width), np.float32), maps), out[FRAME_KEY][i]):
                break
        else:
            near = first if cols[0] == 0 else last
            raise AssertionError(f"view {i}: no frame cut near column {near} gives its padding")
    plain = model_inputs(record, S, TargetConfig(heatmap_stride=0, frame_padding=True), index=3)
    assert np.all(plain[FRAME_KEY] == 1)
