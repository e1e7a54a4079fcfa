"""Data shipped with the simulator (a package so the files install with it)."""
from __future__ import annotations

from pathlib import Path

# One loop of jumping jacks on the default body: CMU joint names with toe joints, T-pose rest,
# Z-X-Y channels, centimetres, 30 fps. Regenerate: python -m tests.drivers.sim.make_sample_bvh
SAMPLE_BVH: Path = Path(__file__).with_name("jumping_jacks.bvh")
