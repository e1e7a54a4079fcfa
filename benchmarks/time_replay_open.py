"""What a ``replay://`` take's open costs, its image sizes checked: a long take opened by this tree's code (and,
with ``--baseline``, by another tree's, turn about), beside reading every image's header and decoding every image.

    .venv/bin/python benchmarks/time_replay_open.py [--frames 3000] [--size 320x240] [--rounds 5]
        [--format png|exif-jpg|tiff|webp] [--take /tmp/ghnerf-replay-open-take[-<format>]]
        [--baseline /path/to/another/checkout]

Writes (once, kept for the next run) a closed take of ``--frames`` frames a camera for two cameras of a smooth
pattern with noise: PNG (``--format png``, as ``record+`` writes it, compression level 1), or JPEG as a phone or
camera writes it (``--format exif-jpg``: quality 95, an APP1 EXIF segment holding an orientation tag of 1 and a
160x120 thumbnail, then a comment, before the frame header; orientation 1 so that code that turns images by it
opens the take too), or as other tools write TIFF (``--format tiff``: OpenCV's, LZW) and WebP (``--format webp``:
OpenCV's, lossy, quality 90). Then prints the median over ``--rounds`` of: ``ReplayRigSource.open()`` of the take
(each in a fresh process, so no run warms the next one's Python caches; only the open is timed), for this tree and,
with ``--baseline``, the other tree's code, the opens taken in turn; every image's ``payload_is_whole`` (what a take
not closed cleanly checks too), in a fresh process too, for each tree in turn; every image's ``header_size``, this
tree's; and, once, decoding every image
(what checking every image's size by decoding would cost). The files are in the page cache (just written or read):
a cold disk adds a read of each file's first block to the header pass. One host, whatever else runs on it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ghnerf_runtime.cli.counts import image_size, positive_count  # noqa: E402
from drivers.backends.recording_format import (  # noqa: E402
    FRAMES, FrameRow, Manifest, encode_image, header_size, load_image, write_manifest,
)
from drivers.sim.placement import RigPlacement  # noqa: E402

#: Run in a child process whose PYTHONPATH is the tree timed: prints the seconds its open took.
_TIMED_OPEN = """
import sys, time
from drivers import create_rig_source
source = create_rig_source("replay://" + sys.argv[1] + "?speed=free")
start = time.perf_counter()
source.open()
print(time.perf_counter() - start)
source.close()
"""

#: Run in a child process whose PYTHONPATH is the tree timed: prints the seconds its payload_is_whole took for every
#: image named on stdin.
_TIMED_WHOLE = """
import sys, time
from pathlib import Path
from drivers.backends.recording_format import payload_is_whole
images = [Path(line) for line in sys.stdin.read().splitlines()]
start = time.perf_counter()
for path in images:
    payload_is_whole(path)
print(time.perf_counter() - start)
"""


#: The take's image format by ``--format``: the manifest's image_format (the recorder's formats only: TIFF and
#: WebP takes are another tool's, the manifest naming PNG) and the images' suffix.
TAKE_FORMATS = {"png": ("png", ".png"), "exif-jpg": ("jpg", ".jpg"), "tiff": ("png", ".tiff"),
                "webp": ("png", ".webp")}


def jpeg_segment(marker: int, payload: bytes) -> bytes:
    """One JPEG marker segment: 0xFF, ``marker``, the length (itself included), ``payload`` (tests/exif_images.py
    builds its tagged images with it too)."""
    return bytes([0xFF, marker]) + struct.pack(">H", len(payload) + 2) + payload


def phone_exif(thumbnail: bytes) -> bytes:
    """An APP1 EXIF payload as a phone writes one, cut down: a little-endian TIFF block whose first directory
    holds the orientation (1: as stored), its second the thumbnail's offset and length, then the thumbnail."""
    first = struct.pack("<H", 1) + struct.pack("<HHIHH", 0x0112, 3, 1, 1, 0) + struct.pack("<I", 26)
    second = struct.pack("<H", 2) + struct.pack("<HHII", 0x0201, 4, 1, 56) + \
        struct.pack("<HHII", 0x0202, 4, 1, len(thumbnail)) + struct.pack("<I", 0)
    return b"Exif\x00\x00" + b"II*\x00" + struct.pack("<I", 8) + first + second + thumbnail


def encoded(image: np.ndarray, take_format: str, thumbnail: bytes) -> bytes:
    if take_format == "png":
        return encode_image(image, "png", 95)
    if take_format == "tiff":
        return cv2.imencode(".tiff", image)[1].tobytes()
    if take_format == "webp":
        return cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 90])[1].tobytes()
    data = encode_image(image, "jpg", 95)
    return data[:2] + jpeg_segment(0xE1, phone_exif(thumbnail)) + jpeg_segment(0xFE, b"a camera app") + data[2:]


def write_take(take: Path, frames: int, width: int, height: int, take_format: str = "png") -> None:
    """A closed two-camera take of ``frames`` frames a camera in ``take_format`` (TAKE_FORMATS; no truth)."""
    rig = RigPlacement(width=width, height=height).build()
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width]
    thumbnail = encode_image(np.full((120, 160, 3), 128, np.uint8), "jpg", 80)
    image_format, suffix = TAKE_FORMATS[take_format]
    rows = []
    for n in range(frames):
        for k, cam in enumerate(rig.pair):
            rel = f"images/{cam.name}/{n:08d}{suffix}"
            (take / rel).parent.mkdir(parents=True, exist_ok=True)
            base = (x + y + 3 * n) % 256
            image = np.clip(base[..., None] + rng.normal(0, 8, (height, width, 3)), 0, 255).astype(np.uint8)
            (take / rel).write_bytes(encoded(image, take_format, thumbnail))
            rows.append(FrameRow(cam.name, n, n * 33_333_333 + k * 1_000_000, rel))
    (take / FRAMES).write_text("".join(row.to_json() + "\n" for row in rows))
    write_manifest(take, Manifest(rig, image_format, "benchmarks/time_replay_open.py", "", complete=True))


def checkout_folder(text: str) -> Path:
    """An argparse ``type=`` for ``--baseline``: a checkout of this project. Another folder was a FileNotFoundError
    traceback from importing its code (here: once the take was written)."""
    if not (Path(text) / "ghnerf_runtime").is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is not a checkout of this project (no ghnerf_runtime/ in it)")
    return Path(text)


def timed_open(code: Path, take: Path) -> float:
    """Seconds ``code``'s ReplayRigSource took to open ``take``, in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    out = subprocess.run([sys.executable, "-c", _TIMED_OPEN, str(take)], env=env, cwd=code, check=True,
                         capture_output=True, text=True).stdout
    return float(out.split()[-1])


def timed_wholes(code: Path, images: list[Path]) -> float:
    """Seconds ``code``'s payload_is_whole took for every one of ``images``, in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    out = subprocess.run([sys.executable, "-c", _TIMED_WHOLE], input="\n".join(map(str, images)), env=env, cwd=code,
                         check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def timed(action) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=positive_count, default=3000, help="frames a camera (default 3000)")
    parser.add_argument("--size", type=image_size, default="320x240", help="image size WxH (default 320x240)")
    parser.add_argument("--rounds", type=positive_count, default=5)
    parser.add_argument("--format", choices=sorted(TAKE_FORMATS), default="png",
                        help="png as record+ writes it (default), exif-jpg as a phone writes it, tiff or webp as "
                             "OpenCV writes them")
    parser.add_argument("--take", type=Path,
                        help="where the take is kept (default /tmp/ghnerf-replay-open-take, -<format> appended "
                             "for a format other than png)")
    parser.add_argument("--baseline", type=checkout_folder,
                        help="another checkout whose open is timed in turn with this one")
    args = parser.parse_args()
    width, height = args.size
    default = "/tmp/ghnerf-replay-open-take" + ("" if args.format == "png" else f"-{args.format}")
    take = (args.take or Path(default)).resolve()
    if not (take / FRAMES).is_file():
        print(f"writing {2 * args.frames} images of {width}x{height} to {take} ...", flush=True)
        write_take(take, args.frames, width, height, args.format)
    images = sorted(take.glob(f"images/*/*{TAKE_FORMATS[args.format][1]}"))
    print(f"take {take} ({args.format}): {len(images)} images of {width}x{height}, {args.rounds} rounds")
    trees = {"this tree": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    opens: dict[str, list[float]] = {name: [] for name in trees}
    wholes: dict[str, list[float]] = {name: [] for name in trees}
    headers = []
    for _ in range(args.rounds):
        for name, code in trees.items():
            opens[name].append(timed_open(code, take))
            wholes[name].append(timed_wholes(code, images))
        headers.append(timed(lambda: [header_size(path) for path in images]))
    for name, code in trees.items():
        print(f"open ({name}, {code}): median {statistics.median(opens[name]):.3f} s "
              f"(min {min(opens[name]):.3f}, max {max(opens[name]):.3f})")
    if args.baseline:
        ratio = statistics.median(opens["this tree"]) / statistics.median(opens["baseline"])
        print(f"open, this tree / baseline: {ratio:.2f}")
    print(f"header_size of every image: median {statistics.median(headers):.3f} s "
          f"({1e6 * statistics.median(headers) / len(images):.1f} us an image)")
    for name in trees:
        print(f"payload_is_whole of every image (a take cut short's check; {name}): median "
              f"{statistics.median(wholes[name]):.3f} s ({1e6 * statistics.median(wholes[name]) / len(images):.1f} us "
              "an image)")
    if args.baseline:
        ratio = statistics.median(wholes["this tree"]) / statistics.median(wholes["baseline"])
        print(f"payload_is_whole, this tree / baseline: {ratio:.2f}")
    decode = timed(lambda: [load_image(path) for path in images])
    print(f"decoding every image (once): {decode:.3f} s ({1e6 * decode / len(images):.0f} us an image)")


if __name__ == "__main__":
    main()
