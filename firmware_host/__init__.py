"""The on-device daemon: joint protocol, sinks (serial / USB / UDP / VMC / file), health."""
