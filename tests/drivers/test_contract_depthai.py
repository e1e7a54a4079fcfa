"""The rig-source contract on ``depthai://``.

Always: the real backend (calibration conversion, Sync stage, message
conversion, error boundary) on a host-only depthai pipeline standing in for
the device (tests/drivers/depthai_host.py). With ``GHNERF_TEST_DEPTHAI=1``: on
an attached OAK device (``GHNERF_DEPTHAI_ID`` picks one; default: the first).
"""
import os

import pytest

from drivers import create_rig_source
from tests.drivers.contract import RigSourceContract
from tests.drivers.depthai_host import HostPipelineLink

HOST_URL = "depthai://?width=160&height=100&mount_height=1.2"


class TestDepthaiHostPipelineContract(RigSourceContract):
    realtime = True

    @classmethod
    def make_source(cls):
        return create_rig_source(f"{HOST_URL}&fps=30", link_factory=HostPipelineLink)

    @classmethod
    def make_stalling_source(cls):
        # the host pipeline sends a group every 10 s (a device goes no slower than fps=1): a read that waited
        # for the next one is seconds past the contract's slack
        return create_rig_source(f"{HOST_URL}&fps=1", link_factory=lambda: HostPipelineLink(fps=0.1))


@pytest.mark.hardware
@pytest.mark.skipif(os.environ.get("GHNERF_TEST_DEPTHAI") != "1",
                    reason="needs an OAK device; set GHNERF_TEST_DEPTHAI=1 (and GHNERF_DEPTHAI_ID) to run")
class TestDepthaiDeviceContract(RigSourceContract):
    realtime = True
    first_timeout_s = 15.0
    slack_s = 0.5

    @classmethod
    def url(cls, fps: int) -> str:
        return f"depthai://{os.environ.get('GHNERF_DEPTHAI_ID', '')}?fps={fps}&width=640&height=400&mount_height=1.2"

    @classmethod
    def make_source(cls):
        return create_rig_source(cls.url(30))

    @classmethod
    def make_stalling_source(cls):
        return create_rig_source(cls.url(1))
