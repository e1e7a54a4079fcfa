"""Fixtures shared by the novel-view tests over the body proxy (``test_proxy_blend``, ``test_novel_painter``), and
every estimator a test makes closed at its end."""
from __future__ import annotations

import numpy as np
import pytest

@pytest.fixture(autouse=True)
def _estimators_closed(monkeypatch):
    """Close every :class:`~ghnerf_runtime.estimator.Estimator` a test made: one left to the garbage collector
    kept its novel-view worker thread alive into later tests (a full run once failed a test that counts them)."""
    from ghnerf_runtime.estimator import Estimator

    made = []
    build = Estimator.__init__

    def build_and_keep(self, *args, **kwargs):
        build(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(Estimator, "__init__", build_and_keep)
    yield
    for est in made:
        est.close()


#: The simulated moment of :func:`shot` (seconds into the motion).
SHOT_T = 0.1


@pytest.fixture(scope="module", params=[5, 11])
def shot(request):
    """A simulated person, two source crops around it and a target between the rig's cameras:
    ``(joints, sources, source RGB in [0, 1], target camera, target BGR image, target truth)``."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.novel_view import interpolate_camera, novel_target

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=request.param, motion="wave"))
    joints = scene.joints_3d(SHOT_T)
    box = np.stack([joints.min(0) - 0.15, joints.max(0) + 0.15])
    sources = [novel_target(c, box, 128) for c in rig.pair]
    rgb = np.stack([scene.render(c, SHOT_T, with_truth=False)[0][..., ::-1].astype(np.float32) / 255
                    for c in sources])
    target = novel_target(interpolate_camera(*rig.pair, 0.5), box, 128)
    image, truth = scene.render(target, SHOT_T)
    return joints, sources, rgb, target, image, truth
