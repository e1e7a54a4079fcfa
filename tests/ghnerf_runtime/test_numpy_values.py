"""The Python API called from a user's own code with NumPy values: config fields as numpy scalars, ``estimate``'s
``sequence`` and ``timestamp_s``, images of other layouts (docs/runtime.md, "NumPy values")."""
from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from ghnerf_runtime import config as C
from ghnerf_runtime.errors import ConfigError, FrameError
from ghnerf_runtime.estimator import Estimator
from ghnerf_runtime.keypoints import KeypointConfigError, KeypointDecoderConfig
from ghnerf_runtime.session import ModelSession
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

sim = pytest.importorskip("drivers.sim")

CONFIGS = (C.SessionConfig, C.RoiConfig, C.TrackingConfig, C.FrameCheckConfig, C.RaysConfig, KeypointDecoderConfig,
           C.HeatmapsConfig, C.Joints3DConfig, C.PresenceConfig, C.SmoothingConfig, C.NovelViewConfig)


def _numpy_twin(value):
    """``value`` (a field's default) as the numpy scalar a user's code would hold, None for other types."""
    if isinstance(value, bool):
        return np.bool_(value)
    if isinstance(value, int):
        return np.int64(value)
    if isinstance(value, float):
        return np.float32(value) if float(np.float32(value)) == value else np.float64(value)
    if isinstance(value, str):
        return np.str_(value)
    return None


def _scalar_fields():
    for cls in CONFIGS:
        for f in dataclasses.fields(cls):
            value = getattr(cls(), f.name)
            if _numpy_twin(value) is not None:
                yield pytest.param(cls, f.name, value, id=f"{cls.__name__}.{f.name}")


@pytest.mark.parametrize("cls, name, value", list(_scalar_fields()))
def test_a_numpy_field_is_stored_as_the_python_value_it_holds(cls, name, value) -> None:
    # np.True_ was refused ("must be true or false"); np.float32 and np.int64 were kept, and config_to_dict's
    # JSON-ready tree then failed in json.dumps
    got = getattr(cls(**{name: _numpy_twin(value)}), name)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize("cls, name, value", [p for p in _scalar_fields()
                                              if type(p.values[2]) in (int, float)])
def test_true_is_no_number(cls, name, value) -> None:
    for flag in (True, np.True_):
        with pytest.raises((ConfigError, KeypointConfigError), match=name):
            cls(**{name: flag})


def test_a_config_built_from_numpy_values_dumps_as_json() -> None:
    cfg = C.EstimatorConfig(roi=C.RoiConfig(keep_frac=np.float32(0.25), supersample=np.int64(2), upright=np.True_),
                            decoder=KeypointDecoderConfig(sigma=np.float32(1.5)),
                            presence=C.PresenceConfig(min_confidence=np.float64(0.3)))
    data = json.loads(json.dumps(C.config_to_dict(cfg), allow_nan=False))
    assert data["roi"]["keep_frac"] == 0.25 and data["decoder"]["sigma"] == 1.5
    assert C.config_from_dict(data) == cfg


def test_a_float_is_no_integer_field() -> None:
    with pytest.raises(ConfigError, match=r"RoiConfig\.supersample: must be an integer"):
        C.RoiConfig(supersample=np.float64(2.0))  # never truncated to 2


@pytest.fixture(scope="module")
def estimator_and_pair(tiny_model_dir):  # noqa: F811
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    pair = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    session = ModelSession.load(C.SessionConfig(model_dir=str(tiny_model_dir), warmup=False),
                                ("encoder", "human", "query"))
    config = C.EstimatorConfig(roi=C.RoiConfig(turn_search=False), heatmaps=C.HeatmapsConfig(flip_test=False))
    return Estimator(session, rig, config), pair


@pytest.mark.parametrize("sequence", [True, np.True_, 2.7, np.float64(3.0), "3"])
def test_a_sequence_that_is_not_a_whole_number_is_refused(estimator_and_pair, sequence) -> None:
    # 2.7 went out in to_json as 2 (and the running count went on 3.7, 4.7), True as pair 1, "3" was a bare TypeError
    est, pair = estimator_and_pair
    with pytest.raises(FrameError, match=r"sequence must be a whole number.*got " + re.escape(repr(sequence))):
        est.estimate(pair, sequence=sequence)


@pytest.mark.parametrize("flag", [True, np.True_, np.array(True)])  # a 0-d array of True was read as 1 s
def test_true_is_no_capture_time(estimator_and_pair, flag) -> None:
    est, pair = estimator_and_pair
    with pytest.raises(FrameError, match=r"timestamp_s must be a finite capture time.*got " + re.escape(repr(flag))):
        est.estimate(pair, timestamp_s=flag)


@pytest.mark.parametrize("stamp, step", [(np.float32(1.7e9), "128"), (np.float32(20000.0), "0.00195"),
                                         (np.float16(5000.0), "4"), (1.7e18, "256")])
def test_a_capture_time_held_in_steps_coarser_than_a_millisecond_is_refused(estimator_and_pair, stamp, step) -> None:
    """A float32 epoch stamp steps by 128 s: every pair of a stream came with one time, which the smoothing took for
    the same pair again (a joint that moved restarted, unsmoothed) and the track's gap test for no gap at all."""
    est, pair = estimator_and_pair
    with pytest.raises(FrameError, match=rf"timestamp_s {re.escape(repr(stamp))} \(\w+\) is held in steps of "
                                         rf"{re.escape(step)} s"):
        est.estimate(pair, timestamp_s=stamp)


@pytest.mark.parametrize("stamp", [np.float32(8000.5), np.float64(1.7e9), 1.7e9, 1_700_000_000, np.int64(10**12)])
def test_a_capture_time_held_to_a_millisecond_is_taken(estimator_and_pair, stamp) -> None:
    est, pair = estimator_and_pair
    est.reset()
    assert est.estimate(pair, timestamp_s=stamp).sequence >= 0


def test_numpy_numbers_and_other_image_layouts_give_the_same_answer(estimator_and_pair) -> None:
    est, (left, right) = estimator_and_pair
    est.reset()
    plain = est.estimate((left, right), sequence=4, timestamp_s=1.5).to_json()
    h, w = left.shape[:2]
    rgba = np.zeros((h + 4, w + 4, 4), np.uint8)
    rgba[2:2 + h, 2:2 + w, :3] = left
    reversed_view = right[:, :, ::-1].copy()[:, :, ::-1]  # BGR again, through negative strides
    reversed_view.setflags(write=False)
    est.reset()
    r = est.estimate((rgba[2:2 + h, 2:2 + w, :3], reversed_view), sequence=np.int64(4), timestamp_s=np.float32(1.5))
    as_numpy = r.to_json()
    assert type(r.sequence) is int and json.dumps(as_numpy, allow_nan=False)
    assert {k: as_numpy[k] for k in ("sequence", "joints_3d", "joints_2d", "missing")} == \
        {k: plain[k] for k in ("sequence", "joints_3d", "joints_2d", "missing")}
