"""The device's headless service: ``ghnerf-daemon`` (``cli``), its config (``config``), main loop
(``service``), health report (``health``) and systemd integration (``notify``). ``docs/daemon.md``."""
from firmware_host.daemon.config import DaemonConfig, DaemonConfigError, HealthConfig, RigConfig, \
    daemon_config_from_dict, load_daemon_config
from firmware_host.daemon.service import Daemon, DaemonStartError

__all__ = ["Daemon", "DaemonStartError", "DaemonConfig", "DaemonConfigError", "RigConfig", "HealthConfig",
           "daemon_config_from_dict", "load_daemon_config"]
