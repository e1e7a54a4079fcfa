"""The device's headless service: ``ghnerf-daemon`` (``cli``), its config (``config``), main loop
(``service``), health report (``health``) and systemd integration (``notify``). ``docs/daemon.md``."""
# First, before the heavy imports below: in ghnerf-daemon, a SIGHUP from now on is recorded, not fatal.
from firmware_host.daemon import early_sighup as _early_sighup

if _early_sighup.is_daemon_process():
    _early_sighup.install()

from firmware_host.daemon.config import DaemonConfig, DaemonConfigError, HealthConfig, RigConfig, \
    daemon_config_from_dict, load_daemon_config
from firmware_host.daemon.service import Daemon, DaemonStartError

__all__ = ["Daemon", "DaemonStartError", "DaemonConfig", "DaemonConfigError", "RigConfig", "HealthConfig",
           "daemon_config_from_dict", "load_daemon_config"]
