"""The device's headless service: ``ghnerf-daemon`` (``cli``), its config (``config``), main loop
(``service``), health report (``health``) and systemd integration (``notify``). ``docs/daemon.md``."""
# First, before the heavy imports below: in ghnerf-daemon, a SIGHUP from now on is recorded, not fatal, and so is
# a stop signal (acted on once the daemon's own stop handlers are in place).
from firmware_host.daemon import early_sighup as _early_sighup

if _early_sighup.is_daemon_process():
    _early_sighup.install()
    _early_sighup.install_stop()

from firmware_host.daemon.config import DaemonConfig, DaemonConfigError, HealthConfig, RigConfig, \
    daemon_config_from_dict, load_daemon_config
from firmware_host.daemon.service import Daemon, DaemonStartError

__all__ = ["Daemon", "DaemonStartError", "DaemonConfig", "DaemonConfigError", "RigConfig", "HealthConfig",
           "daemon_config_from_dict", "load_daemon_config"]
