"""Camera calibration files: import, export and levelling (a calibration CLI is not built yet).

``calibration.formats`` imports and exports foreign calibration files (OpenCV YAML,
anipose TOML); ``calibration.level`` puts an imported rig in the project's frame (gravity
down, floor at y = 0). The rig file itself lives in :mod:`ghnerf_runtime.rig_file`.
"""
