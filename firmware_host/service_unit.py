"""What the installed ghnerf unit (``systemd/ghnerf.service``) lets the service write, said where a write fails.

Under the unit's ``ProtectSystem=strict`` the service writes only its ``RuntimeDirectory=`` and
``StateDirectory=`` (:data:`WRITABLE_FOLDERS`) and its private ``/tmp``; a write anywhere else fails with
EROFS, which ``--validate-config`` (run outside the sandbox) cannot foresee. Both layers that write a file the
config names, the ``file://`` sink and the daemon's status file, add :func:`read_only_hint` to that error, so the
advice is worded once. What ``ProtectHome=`` and ``PrivateTmp=`` hide is ``firmware_host.daemon.sandbox``'s
(a layer above the sinks, which this module is below). A test keeps the folders in step with the unit file.

Standard library only.
"""
from __future__ import annotations

import errno

__all__ = ["WRITABLE_FOLDERS", "read_only_hint"]

#: ``RuntimeDirectory=ghnerf`` and ``StateDirectory=ghnerf``: the folders the service may write.
WRITABLE_FOLDERS = ("/run/ghnerf", "/var/lib/ghnerf")


def read_only_hint(error: BaseException) -> str:
    """For a failed write: ``" (… add the folder with ReadWritePaths= …)"`` when ``error`` is EROFS, the sandbox's
    read-only system, else ``""``. Not for EACCES: a folder's owner or mode (or ``ProtectHome=``, whose folders
    ``ReadWritePaths=`` cannot open) refuses it, and that setting would not help."""
    if not (isinstance(error, OSError) and error.errno == errno.EROFS):
        return ""
    return (f" (read-only: the ghnerf unit writes only under {' and '.join(WRITABLE_FOLDERS)}; add the folder "
            "with ReadWritePaths= in systemctl edit ghnerf)")
