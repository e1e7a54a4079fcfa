"""The rig-source contract on ``replay://``, playing recordings made by ``record+sim://``."""
import pytest

from drivers import ManualClock, create_rig_source, open_rig
from tests.drivers.contract import RigSourceContract


def record(out, sim_options: str, cache, pairs: int) -> None:
    with open_rig(f"record+sim://?{sim_options}&cache={cache}&out={out}", clock=ManualClock()) as source:
        for _ in range(pairs):
            source.read(timeout_s=30.0)  # a ManualClock's seconds: the slow take's pairs are 10 s apart


@pytest.fixture(scope="module")
def takes(tmp_path_factory, sim_cache):
    """A 40-pair take with jitter, offset and drops, and a 0.1 fps take (pairs 10 s apart: the stall)."""
    root = tmp_path_factory.mktemp("replay-contract")
    record(root / "take", "width=160&height=120&jitter_ms=1&offset_ms=2&drop=0.05&seed=2", sim_cache, 40)
    record(root / "slow", "width=160&height=120&fps=0.1", sim_cache, 3)
    return root / "take", root / "slow"


class TestReplayContract(RigSourceContract):
    """Recorded-speed playback on a ManualClock: the recorded timing, exactly."""

    n_pairs = 30
    # the take's first 34 instants (indices 0-33) make 30 pairs: its seed dropped 2 frames of each camera
    # there, each leaving the other camera's frame unpaired. The same free-running: policy=all drops nothing
    expected_stats = {"frames_in": {"left": 32, "right": 32}, "unpaired": {"left": 2, "right": 2},
                      "camera_gaps": {"left": 2, "right": 2}, "pairs_dropped": 0}

    @pytest.fixture(autouse=True, scope="class")
    @classmethod
    def _takes(cls, takes):
        cls.take, cls.slow_take = takes

    @classmethod
    def make_source(cls):
        return create_rig_source(f"replay://{cls.take}?speed=recorded&policy=all", clock=ManualClock())

    @classmethod
    def make_stalling_source(cls):
        return create_rig_source(f"replay://{cls.slow_take}", clock=ManualClock())


class TestReplayContractFreeRunning(TestReplayContract):
    """Free-running playback on the real clock; the slow take still waits at recorded speed."""

    realtime = True

    @classmethod
    def make_source(cls):
        return create_rig_source(f"replay://{cls.take}?speed=free")

    @classmethod
    def make_stalling_source(cls):
        return create_rig_source(f"replay://{cls.slow_take}?speed=recorded")
