"""A pair whose answer is one camera's 2D joints (``PairResult.single_view``) on its way to the sinks: the
daemon's :func:`~firmware_host.joint_frames.estimate_frame` and the wire messages built from it."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_runtime_common import OracleSession, edge128_contract
from firmware_host.joint_frames import estimate_frame
from firmware_host.protocol.constants import UV_SCALE, Flags
from firmware_host.protocol.from_frame import joints2d_messages, joints_message
from ghnerf_runtime.estimator import Estimator

sim = pytest.importorskip("drivers.sim")
drivers = pytest.importorskip("drivers")


@pytest.mark.parametrize("seen", [0, 1])
def test_a_person_seen_by_one_camera_only_reaches_the_wire_as_that_cameras_2d_joints(seen):
    """Every 3D joint missing in JOINTS; the camera that sees the person has its 2D joints in its JOINTS_2D
    (camera index = rig order), the other camera's are all missing."""
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    rendered = [scene.render(c, 0.0) for c in rig.pair]
    visible = np.stack([truth.visible for _, truth in rendered])
    visible[1 - seen] = False  # the other camera sees nobody
    oracle = OracleSession(edge128_contract())
    oracle.set_truth(scene.joints_3d(0.0), visible)
    result = Estimator(oracle, rig).estimate(tuple(img for img, _ in rendered))
    assert result.single_view == rig.pair[seen].name  # (the estimator's own tests check the joints)
    frames = tuple(drivers.Frame(c.name, img, 1_000_000 + k, 0) for k, (c, (img, _)) in enumerate(zip(rig.pair,
                                                                                                       rendered)))
    frame = estimate_frame(drivers.FramePair(frames, 7, rig), result, sequence=3)
    joints = joints_message(frame, send_us=5)
    assert joints.missing.all() and not joints.conf.any()
    messages = joints2d_messages(frame, send_us=5, cameras=[c.name for c in rig.pair])
    assert [m.camera for m in messages] == [0, 1]
    found = ~result.missing_2d[rig.pair[seen].name]
    assert found.sum() >= 6 and np.array_equal(~messages[seen].missing, found)
    np.testing.assert_allclose(messages[seen].uv_q[found] / UV_SCALE, result.joints_2d[rig.pair[seen].name][found],
                               atol=0.5 / UV_SCALE)
    assert messages[1 - seen].missing.all() and not messages[1 - seen].conf.any()
    # flagged, so a receiver tells "one camera saw the person" from "nobody there" (both: every 3D joint missing)
    assert joints.header.flags == Flags.SINGLE_VIEW and {m.header.flags for m in messages} == {Flags.SINGLE_VIEW}


def test_scene_flags_refuse_the_link_s_and_reserved_bits():
    """JointFrame.scene_flags carries the estimate's flags only: DECIMATED / DROPPED are the sink's to set (a
    frame claiming them would tell the receiver of losses that never happened), bit 7 is reserved (bit 6 too until
    session 65, when it became SOMEONE_ELSE)."""
    from tests.firmware_host.joint_stream_helpers import make_frame
    from dataclasses import replace

    frame = make_frame(0)
    assert replace(frame, scene_flags=0x3C).scene_flags == 0x3C
    assert replace(frame, scene_flags=0x7C).scene_flags == 0x7C
    for bad in (Flags.DROPPED, Flags.DECIMATED | Flags.SEVERAL_PEOPLE, 0x80, 0x100, -1):
        with pytest.raises(ValueError, match="JointFrame.scene_flags"):
            replace(frame, scene_flags=int(bad))
