"""``sim://?second=X,Z``: a second person in front of the simulated rig (session 64)."""
import numpy as np
import pytest

from drivers import ManualClock, RigConfigError, create_rig_source, open_rig
from drivers.backends.sim import SimOptions
from drivers.backends.sim_second import MIN_HIPS_APART_M, SECOND_SEED_OFFSET
from drivers.sim import SAMPLE_BVH, SimScene
from drivers.url import RigUrl
from ghnerf_runtime.body25 import JOINT_INDEX

SMALL = "width=64&height=48"
#: The bench's default places' offset (docs/two-people.md: --places -0.5,3.0,0.5,3.4), the subject at (0, 3).
BESIDE = "second=1.0,3.4"


def _options(query: str) -> SimOptions:
    return SimOptions.from_url(RigUrl.parse(f"sim://?{query}"))


def test_the_second_person_stands_where_the_url_says_with_a_seed_of_their_own():
    second = _options(f"seed=3&motion=squat&{BESIDE}").second
    assert second is not None and second.after_s is None
    assert second.scene.position_xz == (1.0, 3.4)
    assert second.scene.seed == 3 + SECOND_SEED_OFFSET
    assert second.scene.motion == "squat"  # the subject's motion unless second_motion= says another
    assert _options(f"{BESIDE}&second_motion=walk&second_after_s=2.5").second.scene.motion == "walk"
    assert _options(f"{BESIDE}&second_after_s=2.5").second.after_s == 2.5
    assert _options(f"bvh={SAMPLE_BVH}&{BESIDE}").second.scene.motion == "wave"  # a clip's subject: waving
    free = _options(f"seed=3&motion=freestyle&{BESIDE}").second.scene
    assert free.motion_params.seed == 3 + SECOND_SEED_OFFSET  # not the subject's curves
    assert _options("seed=3").second is None


@pytest.mark.parametrize(
    ("query", "words"),
    [
        ("second=1", ["second='1'", "two numbers X,Z"]),
        ("second=1,3.4,2", ["second='1,3.4,2'", "two numbers X,Z"]),
        ("second=a,3", ["second='a,3'", "must be a number"]),
        ("second=1,-3", ["second='1,-3'", "z in"]),
        ("second=", ["second= is empty"]),
        ("second=1,3.4&second_motion=moonwalk", ["second_motion", "moonwalk"]),
        ("second=1,3.4&second_after_s=-1", ["second_after_s"]),
        ("second_motion=walk", ["second_motion=", "needs second=X,Z"]),
        ("second_after_s=1", ["second_after_s=", "needs second=X,Z"]),
        ("second=1,3.4&second_speed=2", ["unknown option", "second_speed"]),
    ],
)
def test_bad_second_person_options_are_config_errors_naming_the_option(query, words):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(f"sim://?{SMALL}&cache=off&{query}")
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize(
    ("place", "words"),
    [
        ("6,3", ["camera 'left' does not see the second person at second=6,3"]),  # far right: out of both views
        ("0.1,3.1", ["second=0.1,3.1", "comes within", f"under {MIN_HIPS_APART_M:g} m"]),  # through the subject
    ],
)
def test_a_second_person_the_rig_cannot_film_is_refused(place, words):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(f"sim://?{SMALL}&cache=off&second={place}")
    for word in words:
        assert word in str(info.value)


def _first_pairs(url: str, count: int = 3):
    with open_rig(url, clock=ManualClock()) as source:
        return source, [source.read(timeout_s=1.0) for _ in range(count)]


def test_the_second_person_is_in_the_pixels_where_they_stand_and_the_truth_stays_the_subjects():
    source, two = _first_pairs(f"sim://?{SMALL}&seed=2&cache=off&{BESIDE}")
    _, one = _first_pairs(f"sim://?{SMALL}&seed=2&cache=off")
    second = SimScene(source.options.second.scene)
    for pair_two, pair_one in zip(two, one):
        for cam, f2, f1 in zip(source.rig.pair, pair_two.frames, pair_one.frames):
            changed = np.any(f2.image != f1.image, axis=-1)
            torso = second.joints_3d(f2.scene_time_s)[[JOINT_INDEX["Neck"], JOINT_INDEX["MidHip"]]]
            for u, v in cam.project(torso)[0]:
                assert changed[int(v), int(u)]  # the second person's pixels
            cols = np.nonzero(changed.any(axis=0))[0]
            assert cols.min() > cam.width / 2  # and nothing on the subject's side of the picture (x = 0)
            # the frames carry the subject's truth, as a one-person URL's
            for name in ("mask", "depth", "part_labels", "joints_2d", "visible"):
                assert np.array_equal(getattr(f2.truth, name), getattr(f1.truth, name)), name
            assert np.array_equal(f2.joints_3d, f1.joints_3d)


def test_the_second_person_joins_after_second_after_s():
    url = f"sim://?{SMALL}&seed=2&cache=off&{BESIDE}"
    _, alone = _first_pairs(f"sim://?{SMALL}&seed=2&cache=off", 12)
    _, together = _first_pairs(url, 12)
    _, joining = _first_pairs(f"{url}&second_after_s=0.2", 12)  # 30 fps: from the seventh pair on
    for k, pair in enumerate(joining):
        expected = alone[k] if k < 6 else together[k]
        assert np.array_equal(pair.images[0], expected.images[0]), k


def test_the_cache_key_names_the_second_person_and_a_one_person_loop_is_never_served_for_two(tmp_path):
    def key(query, together=None):
        return create_rig_source(f"sim://?{SMALL}&seed=1&cache=off&{query}").cache_key(together)

    one = key("")
    two = key(BESIDE)
    assert two != one
    assert key("second=-1.0,3.4") != two and key(f"{BESIDE}&second_motion=squat") != two
    assert key(f"{BESIDE}&second_after_s=1", together=False) == one  # its first loop is the one-person entry
    assert key(f"{BESIDE}&second_after_s=1") == two

    _, alone = _first_pairs(f"sim://?{SMALL}&seed=1&cache={tmp_path}", 1)
    with open_rig(f"sim://?{SMALL}&seed=1&cache={tmp_path}&{BESIDE}", clock=ManualClock()) as source:
        assert source.fill_report.source == "rendered"
        pair = source.read(timeout_s=1.0)
    assert not np.array_equal(pair.images[0], alone[0].images[0])
    assert len(list(tmp_path.iterdir())) == 2
    with open_rig(f"sim://?{SMALL}&seed=1&cache={tmp_path}&{BESIDE}&second_after_s=5", clock=ManualClock()) as joining:
        assert joining.fill_report.source == "disk"  # both loops were there already
    assert len(list(tmp_path.iterdir())) == 2
