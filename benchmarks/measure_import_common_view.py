"""How much of the working volume both cameras see: real rigs against stereo_calib's board squares read as metres.

    .venv/bin/python benchmarks/measure_import_common_view.py [--placements 300]

``ghcal import`` warns when the stereo pair sees less than ``calibration.common_view.MIN_COMMON_SHARE`` of the
working volume in common. This prints that share for the repo's rigs (``docs/examples/rig.json``, the rig
``ghcal synth`` films, ``calibration.render.synth_rig``, and the one it filmed until session 68,
``calibration.render.example_rig``, the simulator's default) as they are and as ``ghcal import`` makes them from a
stereo_calib file in the right unit (in the tool's frame with the default volume, and levelled with
``--camera-height`` and ``--pitch``), the least over random training placements, and then each rig's pair
written in board squares and read with ``--units-to-metres 1`` (pairs over 10 m apart are refused anyway).
A tool, not a test.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from calibration.common_view import MIN_COMMON_SHARE, common_view_share  # noqa: E402
from calibration.formats import default_working_volume  # noqa: E402
from calibration.level import level_rig  # noqa: E402
from calibration.render import example_rig, synth_rig  # noqa: E402
from drivers.sim.placement import RigPlacement  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig  # noqa: E402
from ghnerf_runtime.geometry.rig import MAX_BASELINE_M  # noqa: E402
from ghnerf_runtime.rig_file import load_rig  # noqa: E402

SQUARES_M = (0.1, 0.08, 0.05, 0.025)


def as_stereo_calib(rig: Rig, scale: float = 1.0) -> list[Camera]:
    """The pair as stereo_calib hands it over (camera 1's frame is the world), translations times ``scale``."""
    R0, t0 = rig.cameras[0].R, rig.cameras[0].t
    return [Camera(c.name, c.width, c.height, c.K, c.dist, c.R @ R0.T, scale * (c.t - c.R @ R0.T @ t0))
            for c in rig.pair]


def imported(rig: Rig, scale: float = 1.0) -> tuple[Rig, Rig]:
    """``ghcal import``'s two results: the tool's frame with the default volume, and levelled as ``rig`` is
    (its first camera's height and pitch) with the level volume."""
    cams = as_stereo_calib(rig, scale)
    tools = Rig(tuple(cams), default_working_volume(cams), rig_id=rig.rig_id)
    height = -float(rig.cameras[0].center[1])
    pitch = math.degrees(math.asin(float(rig.cameras[0].R[2, 1])))  # the optical axis below the horizon
    return tools, level_rig(tools, camera_height_m=height, pitch_deg=pitch)


def shares_line(name: str, rig: Rig, scale: float = 1.0) -> str:
    """A table row: the baseline as imported, and the share as is (only where the rig's own unit is kept) and in
    both imports."""
    tools, levelled = imported(rig, scale)
    as_is = f"{common_view_share(rig):.3f}" if scale == 1.0 else "-"
    return (f"| {name} | {tools.baseline:.3f} | {as_is} | {common_view_share(tools):.3f} | "
            f"{common_view_share(levelled):.3f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--placements", type=positive_count, default=300, help="random training placements (seeded)")
    args = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[1]
    rigs = {"docs/examples/rig.json": load_rig(root / "docs" / "examples" / "rig.json"),
            "ghcal synth's rig": synth_rig(), "ghcal synth's rig until session 68": example_rig(),
            "simulator default": RigPlacement().build()}
    print(f"warned below {MIN_COMMON_SHARE:g}\n")
    print("| rig | baseline m | share as is | imported, tool's frame | imported, levelled |\n|---|---|---|---|---|")
    for name, rig in rigs.items():
        print(shares_line(name, rig))
    rng = np.random.default_rng(0)
    placements = [RigPlacement.random(rng).build() for _ in range(args.placements)]
    print(f"| {args.placements} training placements (least) | "
          f"{min(r.baseline for r in placements):.2f}-{max(r.baseline for r in placements):.2f} | "
          + " | ".join(f"{min(common_view_share(r) for r in rs):.3f}" for rs in
                       (placements, *zip(*(imported(r) for r in placements)))) + " |")
    print("\nin board squares, read with --units-to-metres 1:\n")
    print("| rig, squares | baseline m | share as is | imported, tool's frame | imported, levelled |\n"
          "|---|---|---|---|---|")
    for name, rig in rigs.items():
        for square in SQUARES_M:
            if rig.baseline / square > MAX_BASELINE_M:
                print(f"| {name}, {1000 * square:g} mm | {rig.baseline / square:.2f} | refused (over "
                      f"{MAX_BASELINE_M:g} m) | | |")
                continue
            print(shares_line(f"{name}, {1000 * square:g} mm", rig, 1 / square))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
