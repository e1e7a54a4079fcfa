"""What ``read_image_or_none`` costs a file (ghnerf-run's stills, ghcal's views, replay's tiled-TIFF fallback):
this tree's against another checkout's ``ghnerf_runtime/image_files.py``, interleaved in one process.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/time_image_read.py --baseline /path/to/other/checkout
        [--size 640x480] [--rounds 400]

Writes a JPEG (quality 95) and a TIFF (OpenCV's, LZW) of a smooth pattern with noise to a temporary folder, then
reads each ``--rounds`` times with each tree's reader, in turn (so a noisy host slows both alike), and prints per
format the median seconds a read for each, the ratio of medians (this tree / baseline) and the spread (the
quartiles of the per-round ratio). The files are in the page cache.
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.time_replay_open import checkout_folder  # noqa: E402
from ghnerf_runtime.cli.counts import image_size, positive_count  # noqa: E402
from ghnerf_runtime import image_files  # noqa: E402


def load_reader(checkout: Path):
    """The ``read_image_or_none`` of ``checkout``'s image_files.py (its other imports from this tree)."""
    spec = importlib.util.spec_from_file_location("baseline_image_files",
                                                  checkout / "ghnerf_runtime" / "image_files.py")
    module = importlib.util.module_from_spec(spec)
    # registered first: a dataclass in it looks its module up in sys.modules while the class is made
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.read_image_or_none


def test_image(width: int, height: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width]
    base = (x + y) % 256
    return np.clip(base[..., None] + rng.normal(0, 8, (height, width, 3)), 0, 255).astype(np.uint8)


def seconds(reader, path: Path) -> float:
    start = time.perf_counter()
    reader(path, cv2.IMREAD_COLOR)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=checkout_folder, required=True, help="the checkout whose reader is compared")
    parser.add_argument("--size", type=image_size, default="640x480")
    parser.add_argument("--rounds", type=positive_count, default=400)
    args = parser.parse_args()
    width, height = args.size
    old_reader, new_reader = load_reader(args.baseline), image_files.read_image_or_none
    image = test_image(width, height)
    with tempfile.TemporaryDirectory() as folder:
        files = {".jpg": cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])[1],
                 ".tiff": cv2.imencode(".tiff", image)[1]}
        for suffix, data in files.items():
            path = Path(folder) / f"frame{suffix}"
            path.write_bytes(data.tobytes())
            assert np.array_equal(old_reader(path, cv2.IMREAD_COLOR), new_reader(path, cv2.IMREAD_COLOR))
            old, new = [], []
            for _ in range(args.rounds):
                old.append(seconds(old_reader, path))
                new.append(seconds(new_reader, path))
            ratios = sorted(n / o for n, o in zip(new, old))
            q1, _, q3 = statistics.quantiles(ratios, n=4)
            print(f"{suffix[1:]:>4} {width}x{height}: baseline {statistics.median(old) * 1e3:.3f} ms, "
                  f"this tree {statistics.median(new) * 1e3:.3f} ms, ratio of medians "
                  f"{statistics.median(new) / statistics.median(old):.3f} (per-round ratio quartiles "
                  f"{q1:.3f}-{q3:.3f}, {args.rounds} rounds)")


if __name__ == "__main__":
    main()
