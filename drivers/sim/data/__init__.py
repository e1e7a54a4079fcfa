"""Data shipped with the simulator (a package so the files install with it)."""
from __future__ import annotations

from pathlib import Path

# One loop of jumping jacks on the default body: CMU joint names with toe joints, T-pose rest,
# Z-X-Y channels, centimetres, 30 fps. Regenerate with tests/drivers/sim/make_sample_bvh.py.
SAMPLE_BVH: Path = Path(__file__).with_name("jumping_jacks.bvh")
