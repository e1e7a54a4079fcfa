"""``ghnerf_runtime.rays_recheck``: when the cached whole-volume verdict of a rejected crop on the rays holds."""
from __future__ import annotations

import numpy as np
import pytest

from ghnerf_runtime.config import ConfigError, FrameCheckConfig
from ghnerf_runtime.rays_recheck import VolumeVerdict, mean_level


class _Tracker:
    resets = 0


def test_mean_level_is_over_the_pixels_that_show_the_frame():
    plane = np.zeros((4, 4), np.float32)
    plane[:, 2:] = 0.5
    inside = np.zeros((4, 4), bool)
    inside[:, 2:] = True
    assert mean_level(plane, inside, 255.0) == pytest.approx(127.5)
    assert mean_level(plane, None, 255.0) == pytest.approx(63.75)
    assert np.isnan(mean_level(plane, np.zeros((4, 4), bool), 255.0))


def test_a_verdict_holds_only_for_the_same_camera_tracker_reason_and_brightness_within_its_reuses():
    state, tracker = object(), _Tracker()
    verdict = VolumeVerdict(state, tracker, 0, "flat", 100.0, 2, 16.0)
    assert verdict.holds(state, tracker, "flat", 100.0 + 16.0)
    assert not verdict.holds(state, tracker, "flat", 100.0 + 17.0)  # darkened: a cap, a hand
    assert not VolumeVerdict(state, tracker, 0, "flat", 100.0, 2, 4.0).holds(state, tracker, "flat", 105.0)
    assert not verdict.holds(state, tracker, "flat", float("nan"))
    assert not verdict.holds(state, tracker, "noise", 100.0)
    assert not verdict.holds(object(), tracker, "flat", 100.0)  # another crop turn's camera state
    assert not verdict.holds(state, _Tracker(), "flat", 100.0)  # another (a kept turn's) tracker
    last = verdict.reused().reused()
    assert last.reuses_left == 0 and not last.holds(state, tracker, "flat", 100.0)
    tracker.resets = 1
    assert not verdict.holds(state, tracker, "flat", 100.0)


@pytest.mark.parametrize("value", [0, 1001, 2.5, True, None])
def test_volume_recheck_every_must_be_a_whole_number_of_pairs(value):
    with pytest.raises(ConfigError, match="volume_recheck_every"):
        FrameCheckConfig(volume_recheck_every=value)


def test_volume_recheck_levels_defaults_to_16_and_must_be_a_level_from_0_to_255():
    assert FrameCheckConfig().volume_recheck_levels == 16.0
    assert FrameCheckConfig(volume_recheck_levels=0).volume_recheck_levels == 0  # any move checks again


@pytest.mark.parametrize("value", [-1.0, 255.5, float("nan"), float("inf"), True, None, "16"])
def test_volume_recheck_levels_out_of_range_is_an_error_naming_the_field_and_value(value):
    with pytest.raises(ConfigError, match="volume_recheck_levels") as e:
        FrameCheckConfig(volume_recheck_levels=value)
    assert repr(value) in str(e.value)
