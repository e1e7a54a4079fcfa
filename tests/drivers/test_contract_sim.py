"""The rig-source contract on ``sim://`` (ManualClock: instant and exact)."""
import pytest

from drivers import ManualClock, create_rig_source
from tests.drivers.contract import RigSourceContract

URL = "sim://?width=160&height=120&jitter_ms=1&offset_ms=2&drop=0.05&seed=1"


class TestSimContract(RigSourceContract):
    n_pairs = 40
    # 49 captures a camera (indices 0-48) for 40 pairs; seed 1 drops 4 left and 5 right (index gaps), and
    # each dropped frame leaves the other camera's frame of that instant unpaired
    expected_stats = {"frames_in": {"left": 45, "right": 44}, "unpaired": {"left": 5, "right": 4},
                      "camera_gaps": {"left": 4, "right": 5}, "pairs_dropped": 0}

    @pytest.fixture(autouse=True, scope="class")
    @classmethod
    def _use_cache(cls, sim_cache):
        cls.cache = sim_cache

    @classmethod
    def make_source(cls):
        return create_rig_source(f"{URL}&cache={cls.cache}", clock=ManualClock())

    @classmethod
    def make_stalling_source(cls):
        # a pair every 2 s: after the first one, nothing for longer than the timeout
        return create_rig_source(f"sim://?width=160&height=120&fps=0.5&cache={cls.cache}", clock=ManualClock())


class TestSimContractRealClock(RigSourceContract):
    """The same promises on the real clock (timeouts measured in wall time)."""

    realtime = True
    n_pairs = 10

    @pytest.fixture(autouse=True, scope="class")
    @classmethod
    def _use_cache(cls, sim_cache):
        cls.cache = sim_cache

    @classmethod
    def make_source(cls):
        return create_rig_source(f"sim://?width=160&height=120&fps=60&cache={cls.cache}")

    @classmethod
    def make_stalling_source(cls):
        # a pair every 10 s: a read that waited for the next one is seconds past the contract's slack
        return create_rig_source(f"sim://?width=160&height=120&fps=0.1&cache={cls.cache}")
