"""The pairing options every rig URL takes (``tolerance_ms``, ``policy``, ``max_pending``), read in one place
(``drivers.pairing_options``): each backend gets the same names, bounds and messages."""
from __future__ import annotations

import pytest

from drivers import DropPolicy, ManualClock, PairingConfig, RigConfigError, create_rig_source, open_rig
from drivers.backends.depthai.options import DepthaiOptions
from drivers.backends.opencv import OpenCVOptions, OpenCVRigSource
from drivers.pairing import MAX_HELD
from drivers.pairing_options import PairingOptions, take_pairing_options
from drivers.url import RigUrl

#: A URL of each backend, to which the pairing options are appended ('&' and more options).
URLS = {
    "sim": "sim://?width=32&height=24&cache=off",
    "replay": "replay:///no/such/take?speed=free",
    "opencv": "opencv://?first=/dev/video0&second=/dev/video2",
    "depthai": "depthai://?fps=30",
}


def pairing_of(scheme: str, options: str) -> PairingConfig:
    """The pairing config the backend's URL parsing makes of ``options``, without opening anything."""
    url = RigUrl.parse(f"{URLS[scheme]}&{options}")
    if scheme == "sim":
        return create_rig_source(url.url).pairing
    if scheme == "opencv":
        return OpenCVRigSource(OpenCVOptions.from_url(url)).pairing
    if scheme == "depthai":
        return DepthaiOptions.from_url(url).pairing
    raise AssertionError(f"no parse-only path for {scheme}")


@pytest.mark.parametrize("scheme", ["sim", "opencv", "depthai"])
def test_max_pending_reaches_the_pairing_config_of_every_backend(scheme):
    assert pairing_of(scheme, "max_pending=20").max_pending == 20
    assert pairing_of(scheme, "tolerance_ms=5").max_pending == PairingConfig.max_pending  # the default: 8


@pytest.mark.parametrize("scheme", sorted(URLS))
@pytest.mark.parametrize("value", ["0", str(MAX_HELD + 1), "8.5", "-1"])
def test_a_max_pending_out_of_bounds_is_refused_naming_the_option_and_value(scheme, value):
    # replay:// refuses it before looking for the take
    with pytest.raises(RigConfigError, match=rf"option max_pending={value!r}"):
        create_rig_source(f"{URLS[scheme]}&max_pending={value}")


def test_replay_takes_max_pending_too(tmp_path, sim_cache):
    take = tmp_path / "take"
    with open_rig(f"record+sim://?width=32&height=24&cache={sim_cache}&out={take}", clock=ManualClock()) as source:
        source.read(timeout_s=5.0)
    source = create_rig_source(f"replay://{take}?max_pending={MAX_HELD}")
    assert (source.pairing.max_pending, source.pairing.policy) == (MAX_HELD, DropPolicy.ALL)


def test_the_shared_options_keep_each_backends_defaults():
    url = RigUrl.parse("replay:///take?tolerance_ms=4")
    assert take_pairing_options(url, policy=DropPolicy.ALL) == PairingOptions(4.0, DropPolicy.ALL, 8)
    assert take_pairing_options(RigUrl.parse("opencv://?x=1")).tolerance_ms is None  # the backend's own
    assert PairingOptions(max_pending=12).config(20.0) == PairingConfig(tolerance_ms=20.0, max_pending=12)
    with pytest.raises(RigConfigError, match=r"option tolerance_ms='2000'"):
        take_pairing_options(RigUrl.parse("sim://?tolerance_ms=2000"), max_tolerance_ms=1000.0)
