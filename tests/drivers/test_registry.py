"""The backend registry: unknown schemes, lazy imports, record+ wrapping."""
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from drivers import BACKENDS, BackendNotAvailableError, RigConfigError, create_rig_source
from drivers.registry import backend_class


def test_unknown_scheme_names_it_and_lists_the_known_ones():
    with pytest.raises(BackendNotAvailableError) as info:
        create_rig_source("v4l2:///dev/video0")
    assert "'v4l2'" in str(info.value)
    for known in ("sim", "replay", "depthai"):
        assert known in str(info.value)


def test_a_backend_module_that_cannot_import_is_not_available():
    table = {"ghost": ("drivers.backends.no_such_module", "Ghost")}
    with pytest.raises(BackendNotAvailableError, match="ghost"):
        backend_class("ghost", table)


def test_registry_entries_resolve_to_rig_sources_with_their_scheme():
    from drivers import RigSource

    for scheme in BACKENDS:
        cls = backend_class(scheme)
        assert issubclass(cls, RigSource) and cls.scheme == scheme


def test_record_without_out_is_a_config_error():
    with pytest.raises(RigConfigError, match="out="):
        create_rig_source("record+sim://?fps=30")


def _run(code: str) -> str:
    result = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120,
        cwd=Path(__file__).resolve().parents[2],  # the repository root: `import drivers` works from anywhere
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_importing_drivers_imports_no_backend_and_not_depthai():
    out = _run(
        """
        import sys
        import drivers
        loaded = sorted(m for m in sys.modules if m == "depthai" or m.startswith("drivers.backends."))
        print(loaded)
        """
    )
    assert out.strip() == "[]"


def test_opening_sim_and_replay_never_imports_depthai(tmp_path):
    out = _run(
        f"""
        import sys
        from drivers import ManualClock, open_rig
        url = "record+sim://?width=32&height=24&cache=off&out={tmp_path / 'take'}"
        with open_rig(url, clock=ManualClock()) as rig:
            rig.read(timeout_s=1.0)
        with open_rig("replay://{tmp_path / 'take'}?speed=free") as rig:
            rig.read(timeout_s=1.0)
        print("depthai" in sys.modules)
        """
    )
    assert out.strip().splitlines()[-1] == "False"


def test_innermost_url_takes_off_every_wrapper_the_registry_knows(monkeypatch):
    from drivers import wrappers

    assert wrappers.innermost_url("record+opencv://?first=a.avi&out=take") == "opencv://?first=a.avi&out=take"
    assert wrappers.innermost_url("opencv://?first=a.avi") == "opencv://?first=a.avi"
    assert wrappers.innermost_url("replay://record+x") == "replay://record+x"  # a prefix only at the start
    monkeypatch.setitem(wrappers.WRAPPERS, "spy+", ("drivers.backends.record", "RecordingRigSource"))
    assert wrappers.innermost_url("spy+record+sim://?fps=30") == "sim://?fps=30"


def test_create_rig_source_wraps_through_the_registry_s_wrappers(monkeypatch):
    # the wrappers are one table (drivers.wrappers.WRAPPERS), read by create_rig_source and innermost_url alike
    from drivers import wrappers
    from drivers.backends.record import RecordingRigSource

    wrapped = []

    class Spy(RecordingRigSource):
        @classmethod
        def wrap(cls, inner_url, factory, **kwargs):
            wrapped.append(inner_url.url)
            return factory(f"{inner_url.scheme}://{inner_url.target}", **kwargs)

    monkeypatch.setitem(wrappers.WRAPPERS, "spy+", (__name__, "_SPY"))
    monkeypatch.setattr(sys.modules[__name__], "_SPY", Spy, raising=False)
    source = create_rig_source("spy+sim://")
    assert wrapped == ["sim://"] and source.scheme == "sim"
    with pytest.raises(BackendNotAvailableError, match="record\\+<url>, spy\\+<url>"):
        create_rig_source("v4l2:///dev/video0")


def test_the_wrappers_helpers_have_one_import_path():
    """The review of session 66's merges: the registry re-exported ``innermost_url`` and ``RECORD_PREFIX`` from
    :mod:`drivers.wrappers`, and ``ghcal capture`` imported the one from the registry while the demo and the daemon's
    config imported it from ``drivers.wrappers``: two ways to one function. Code imports them from
    ``drivers.wrappers`` only."""
    from drivers import registry

    assert not hasattr(registry, "innermost_url") and not hasattr(registry, "RECORD_PREFIX")
    assert set(registry.__all__) == {"BACKENDS", "backend_class", "create_rig_source", "open_rig"}


@pytest.mark.parametrize("url", [None, b"sim://", 5, Path("sim://")])
def test_a_rig_url_that_is_not_text_is_refused_naming_it(url):
    # the path checks and the wrapper prefixes read it as text first: AttributeError: 'NoneType' object has no
    # attribute 'startswith', naming no URL (a config value left null)
    with pytest.raises(RigConfigError, match=r"rig URL must be text, 'scheme://target\?options', got "):
        create_rig_source(url)
