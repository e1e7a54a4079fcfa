"""Camera calibration: the ``ghcal`` CLI (board, capture, solve, check, synth), foreign files, levelling.

``calibration.board`` defines the printed ChArUco board, ``calibration.detect`` finds it in an image,
``calibration.solve`` turns views into a levelled rig (intrinsics, the pair's relative pose, the floor),
``calibration.check`` tests a rig file against new views, ``calibration.capture`` reads and writes the
folders of views, ``calibration.render`` renders views of a known rig (for trying ``ghcal`` without
cameras, and for its tests), and ``calibration.cli`` is ``ghcal`` (docs/calibration.md), which asks whether
an output can be written before the work (``ghnerf_runtime.cli.output_path``, as the other tools do).
``calibration.formats`` imports and exports foreign calibration files (OpenCV YAML, anipose TOML);
``calibration.level`` puts an imported rig in the project's frame (gravity down, floor at y = 0). The
rig file itself lives in :mod:`ghnerf_runtime.rig_file`.
"""
