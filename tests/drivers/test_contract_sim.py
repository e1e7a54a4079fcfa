"""The rig-source contract on ``sim://`` (ManualClock: instant and exact)."""
import pytest

from drivers import ManualClock, create_rig_source
from tests.drivers.contract import RigSourceContract

URL = "sim://?width=160&height=120&jitter_ms=1&offset_ms=2&drop=0.05&seed=1"


class TestSimContract(RigSourceContract):
    n_pairs = 40

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
        return create_rig_source(f"sim://?width=160&height=120&fps=0.5&cache={cls.cache}")
