"""What the ghnerf unit's sandbox (``systemd/ghnerf.service``) hides from the service, said before it bites.

``ProtectHome=yes`` makes ``/home``, ``/root`` and ``/run/user`` empty and inaccessible to the service, and
``PrivateTmp=yes`` gives it a ``/tmp`` and ``/var/tmp`` of its own. A model folder, rig file, recording, status
file or ``file://`` sink there passes ``ghnerf-daemon --validate-config`` (run from a login shell, outside the
sandbox), and the service then says only "no such file" or "permission denied". So ``--validate-config`` warns
of such paths (:func:`sandbox_warnings`), and the service's own errors for them carry the same advice when it runs
under systemd (:func:`service_hint`).

``ReadOnlyPaths=`` / ``ReadWritePaths=`` cannot open a path below ``/home`` again under ``ProtectHome=yes``:
nothing is left there to remount (systemd issue 7153). ``ProtectHome=tmpfs`` with ``BindReadOnlyPaths=``
(``BindPaths=`` for a path the service writes) can, in a drop-in (``systemctl edit ghnerf``); moving the file
is simpler. A test keeps these folders in step with the unit file's settings.
"""
from __future__ import annotations

import os

from drivers.url_paths import url_files
from firmware_host.daemon.config import DaemonConfig
from firmware_host.errors import FirmwareHostError
from firmware_host.sinks.file_sink import FileSink

__all__ = ["HOME_FOLDERS", "PRIVATE_TMP_FOLDERS", "hidden_by_sandbox", "sandbox_advice", "configured_paths",
           "sandbox_warnings", "under_systemd", "service_hint", "rig_url_hint"]

#: Hidden by the unit's ``ProtectHome=yes``.
HOME_FOLDERS = ("/home", "/root", "/run/user")
#: The service's own under the unit's ``PrivateTmp=yes``: it does not see what is there outside.
PRIVATE_TMP_FOLDERS = ("/tmp", "/var/tmp")


def _under(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder + "/")


def hidden_by_sandbox(path: str | os.PathLike) -> str | None:
    """The folder of :data:`HOME_FOLDERS` or :data:`PRIVATE_TMP_FOLDERS` that keeps ``path`` from the service, or
    None. The path as written and where its links lead are both looked at: the service can follow neither a path
    through ``/home`` nor a link into it (``/opt/models`` -> ``/home/me/models``)."""
    written = os.path.abspath(os.fspath(path))
    for candidate in dict.fromkeys((written, os.path.realpath(written))):
        for folder in HOME_FOLDERS + PRIVATE_TMP_FOLDERS:
            if _under(candidate, folder):
                return folder
    return None


def sandbox_advice(path: str | os.PathLike, *, written: bool = False) -> str | None:
    """Why the service cannot see ``path``, and what to do (None: it can see it). ``written``: the service writes
    it (a status file, a ``file://`` sink)."""
    folder = hidden_by_sandbox(path)
    if folder is None:
        return None
    move = "move it under /var/lib/ghnerf (the service's own folder) or another system folder"
    if folder in PRIVATE_TMP_FOLDERS:
        what = ("what it writes there no one else sees, and it goes when the service stops" if written
                else "it does not see this one")
        return f"under {folder}, which under the ghnerf unit's PrivateTmp=yes is the service's own ({what}): {move}"
    bind = "BindPaths" if written else "BindReadOnlyPaths"
    return (f"under {folder}, which the ghnerf unit's ProtectHome=yes hides from the service: {move}, or let the "
            f"service see it in a drop-in (systemctl edit ghnerf): ProtectHome=tmpfs and "
            f"{bind}={os.path.abspath(os.fspath(path))} (ReadWritePaths=/ReadOnlyPaths= cannot open a path there "
            "under ProtectHome=yes)")


def _rig_url_files(url: str) -> list[tuple[str, bool]]:
    """The files a rig URL names (``drivers.url_paths.url_files``), each with whether it is written (``sim://?cache=``,
    the folder its loop is rendered into)."""
    return [(path, part == "cache") for part, path in url_files(url)]


def configured_paths(config: DaemonConfig) -> list[tuple[str, str, bool]]:
    """Every path the config names: ``(key, path, written)``; relative ones as the daemon reads them (its config
    file's folder was applied on load)."""
    paths = [("estimator.session.model_dir", str(config.estimator.session.model_dir), False)]
    if config.health.status_file:
        paths.append(("health.status_file", str(config.health.status_file), True))
    paths += [("rig.url", path, written) for path, written in _rig_url_files(config.rig.url)]
    for i, url in enumerate(config.sinks):
        if url.lower().startswith("file:"):
            try:
                paths.append((f"sinks[{i}]", FileSink.from_url(url).path, True))
            except FirmwareHostError:
                pass  # check_sink_urls names it
    return paths


def sandbox_warnings(config: DaemonConfig) -> list[str]:
    """One line per configured path the installed service could not see (``--validate-config`` prints them: a
    warning, not a failure, as the config may be meant for a run outside the service)."""
    out = []
    for key, path, written in configured_paths(config):
        advice = sandbox_advice(path, written=written)
        if advice is not None:
            out.append(f"{key}: {path} is {advice}")
    return out


def under_systemd() -> bool:
    """Whether this process was started by systemd (a service sets ``INVOCATION_ID``)."""
    return bool(os.environ.get("INVOCATION_ID"))


def service_hint(path: str | os.PathLike, *, written: bool = False) -> str:
    """For an error about ``path`` (not found, not readable): ``" (… is under /home, …)"`` when this runs under
    systemd and the sandbox hides it, else ``""``. Outside systemd the path is really missing."""
    if not under_systemd():
        return ""
    advice = sandbox_advice(path, written=written)
    return "" if advice is None else f" (the path is {advice})"


def rig_url_hint(url: str) -> str:
    """:func:`service_hint` for the first file a rig URL names that the sandbox hides (a recording under /home
    that the service waits for, as for one not made yet), else ``""``."""
    for path, written in _rig_url_files(url):
        hint = service_hint(path, written=written)
        if hint:
            return hint
    return ""
