"""``benchmarks/measure_left_right.py``'s mirrored source: the keypoint graph sees the mirrored crops, and its heatmaps
come back where the filmed joints are, each channel still the model's own (not exchanged left for right, as the flip
test's un-mirroring does): so a channel's rate on the mirrored scene tells the model's labels from the scene's sides."""
from __future__ import annotations

import numpy as np

from benchmarks.measure_left_right import MirroringSession, sided_means, side_rates
from ghnerf_runtime.body25 import FLIP_INDEX, JOINT_INDEX
from ghnerf_runtime.flip_test import flip_averaged, mirror_images


class BrightestColumn:
    """A stand-in keypoint graph: RShoulder's map peaks at each crop's brightest column, LShoulder's at the column
    mirrored from it (a model that reads which side of the crop a thing is on), every other map flat."""

    def __init__(self):
        self.seen_P = None

    def run(self, graph, feeds):
        self.seen_P = feeds.get("src_P")
        images = feeds["images"]
        s, _, h, w = images.shape
        heat = np.zeros((s, 25, h, w), np.float32)
        for i in range(s):
            column = int(images[i].sum(axis=(0, 1)).argmax())
            heat[i, JOINT_INDEX["RShoulder"], :, column] = 1.0
            heat[i, JOINT_INDEX["LShoulder"], :, w - 1 - column] = 1.0
        return {"encoder_heatmaps": heat}


class RandomLinear:
    """A stand-in keypoint graph with no symmetry at all: each channel a random weighting of each pixel."""

    def __init__(self, rng):
        self.weights = rng.normal(size=(25, 3, 8, 8)).astype(np.float32)

    def run(self, graph, feeds):
        return {"encoder_heatmaps": np.einsum("schw,jchw->sjhw", feeds["images"], self.weights)}


def test_mirrored_heatmaps_come_back_in_place_with_the_model_s_channels():
    graph = BrightestColumn()
    images = np.zeros((2, 3, 8, 8), np.float32)
    images[:, :, :, 2] = 1.0  # the bright thing in column 2 of each crop
    src_P = np.tile(np.eye(3, 4), (2, 1, 1))
    out = MirroringSession(graph).run("human", {"images": images, "src_P": src_P})["encoder_heatmaps"]
    seen_P = graph.seen_P
    plain = graph.run("human", {"images": images})["encoder_heatmaps"]
    # the model saw the thing in column 5: its RShoulder channel comes back on column 2, where the thing is
    assert out[:, JOINT_INDEX["RShoulder"]].sum(axis=(0, 1)).argmax() == 2
    # ... and its LShoulder channel where it put it in the mirrored crop, mirrored back: column 5 (plain: 5 as well)
    assert out[:, JOINT_INDEX["LShoulder"]].sum(axis=(0, 1)).argmax() == 5
    assert plain[:, JOINT_INDEX["LShoulder"]].sum(axis=(0, 1)).argmax() == 5
    # the graph was given the mirrored crops' cameras with them: column u -> 7 - u
    assert np.allclose(seen_P[0, 0], [-1.0, 0.0, 7.0, 0.0])


def test_other_graphs_run_unmirrored():
    graph = BrightestColumn()
    images = np.zeros((1, 3, 4, 4), np.float32)
    images[:, :, :, 0] = 1.0
    out = MirroringSession(graph).run("render_heat", {"images": images})["encoder_heatmaps"]
    assert out[0, JOINT_INDEX["RShoulder"]].sum(axis=0).argmax() == 0


def test_side_rates_and_sided_means_count_per_view_and_both():
    found = np.zeros((4, 2, 25), bool)
    found[:, 0, JOINT_INDEX["RHip"]] = True  # view 0 always, view 1 half the pairs
    found[:2, 1, JOINT_INDEX["RHip"]] = True
    rates = side_rates(found)
    assert rates["RHip"] == (1.0, 0.5, 0.5) and rates["LHip"] == (0.0, 0.0, 0.0)
    right, left = sided_means(found)
    assert np.isclose(right, 6 / (4 * 2 * 11)) and left == 0.0


def test_the_flip_test_on_mirrored_crops_is_its_figures_with_left_and_right_exchanged():
    """Why the tool runs no mirrored source with the flip test on (``FLIP_TEST_MIRRORED_NOTE``): whatever the model,
    the flip test of the mirroring session is the plain flip test's heatmaps with each channel its mirror's."""
    rng = np.random.default_rng(0)
    graph = RandomLinear(rng)
    crops = rng.random((2, 3, 8, 8)).astype(np.float32)
    mirror = MirroringSession(graph)
    plain = flip_averaged(graph.run("human", {"images": crops})["encoder_heatmaps"],
                          graph.run("human", {"images": mirror_images(crops)})["encoder_heatmaps"])
    mirrored = flip_averaged(mirror.run("human", {"images": crops})["encoder_heatmaps"],
                             mirror.run("human", {"images": mirror_images(crops)})["encoder_heatmaps"])
    assert np.array_equal(mirrored, plain[:, list(FLIP_INDEX)])
    assert not np.array_equal(mirrored, plain)  # (a model with sides of its own: the check can fail)
