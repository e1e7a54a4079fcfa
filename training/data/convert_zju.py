"""Convert one ZJU-MoCap subject folder into a split of a cached dataset (``training.data.zju_samples.convert_zju``).

Example (docs/dataset.md, "ZJU-MoCap")::

    python -m training.data.convert_zju /data/zju/CoreView_313 --out data/zju128 --split train_313 \\
        --res 128 --view-set 0,3,1,2

The subject folder must hold ``annots.npy``, the images folder of every camera the view sets use and a mask folder
(``mask/``, or ``mask_cihp/`` with ``--mask-dir``); each missing one is named (exit 2) before anything converts.
Converting into a folder that already holds the split rewrites that split whole; the other splits stay.
Torch-free, like ``training.data.generate``.
"""
from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence

from ghnerf_runtime.cli.sigterm import exit_status, sigterm_as_interrupt, stop_words
from ghnerf_runtime.path_check import user_path_as_path
from training.data.errors import DataConfigError, DatasetError
from training.data.zju import MASK_DIRS
from training.data.zju_samples import ZjuConfig, convert_zju, split_replaced

log = logging.getLogger("training.data.convert_zju")

_DEFAULT = ZjuConfig()


def _view_set(text: str) -> tuple[int, ...]:
    """``0,3,1,2``: camera indices, the two sources first."""
    try:
        cams = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected camera indices separated by commas (0,3,1,2), got {text!r}") \
            from None
    return cams


def _frames(text: str) -> tuple[int, int, int]:
    """``START:STOP:STEP`` (``STOP`` -1: to the last frame); ``START:STOP`` and ``START`` take the rest's defaults."""
    parts = text.split(":")
    if not 1 <= len(parts) <= 3:
        raise argparse.ArgumentTypeError(f"expected START:STOP:STEP, got {text!r}")
    try:
        values = [int(v) for v in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected whole numbers START:STOP:STEP, got {text!r}") from None
    return tuple(values + list(_DEFAULT.frames[len(values):]))  # type: ignore[return-value]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training.data.convert_zju", description=__doc__.split("\n")[0])
    p.add_argument("subject", type=user_path_as_path, help="the ZJU-MoCap subject folder (holding annots.npy), e.g. CoreView_313")
    p.add_argument("--out", required=True, type=user_path_as_path, help="dataset folder (created, or a split added or rewritten)")
    p.add_argument("--split", default="train", help="split name, e.g. train_313 (letters, digits, _; default train)")
    p.add_argument("--res", type=int, default=_DEFAULT.resolution, help="crop resolution S (multiple of 8 in 32..512)")
    p.add_argument("--view-set", dest="view_sets", type=_view_set, action="append", metavar="C,C[,C...]",
                   help="camera indices of one view set, the two sources first (repeat for several; all of one "
                        f"length); default {','.join(map(str, _DEFAULT.view_sets[0]))}")
    p.add_argument("--frames", type=_frames, default=_DEFAULT.frames, metavar="START:STOP:STEP",
                   help="frames of annots.npy's ims to convert (STOP -1: to the last); default 0:-1:1")
    p.add_argument("--joints-2d-from", choices=("auto", "keypoints3d", "kpts2d"), default=_DEFAULT.joints_2d_from,
                   help="2D joint targets: projected 3D joints (keypoints3d), the images' 2D keypoints (kpts2d), or "
                        "the first when enough 3D joints are known (auto)")
    p.add_argument("--mask-dir", choices=MASK_DIRS, default=_DEFAULT.mask_dir, help="the subject's mask folder")
    p.add_argument("--mask-fallback", action="store_true",
                   help="where --mask-dir lacks an image's mask, read the other mask folder's")
    p.add_argument("--skip-missing-masks", action="store_true",
                   help="leave out the samples with a view whose mask is missing (counted), instead of stopping")
    p.add_argument("--margin", type=float, default=_DEFAULT.margin_frac, help="ROI margin, a share of its size")
    p.add_argument("--min-roi-size", type=int, default=_DEFAULT.min_roi_size, help="smallest ROI side, image pixels")
    p.add_argument("--min-confidence", type=float, default=_DEFAULT.min_confidence,
                   help="2D keypoints at or below this confidence are missing")
    p.add_argument("--bbox-margin", type=float, default=_DEFAULT.bbox_margin_m,
                   help="growth of the 3D joints' box into the subject box, metres")
    p.add_argument("--shard-size", type=int, default=64, help="samples per shard (1..100000)")
    p.add_argument("-v", "--verbose", action="store_true")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Exit 0 when converted; 2 for a bad option value or an unusable subject folder (the message names the option
    or the file), 130 for Ctrl-C and 143 for a SIGTERM: the previous split, if any, is left as it was, or, where the
    stop came during the swap (held over it), the new split is in place; the message says which."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(message)s")
    try:
        config = ZjuConfig(resolution=args.res, view_sets=tuple(args.view_sets or _DEFAULT.view_sets),
                           frames=args.frames, margin_frac=args.margin, min_roi_size=args.min_roi_size,
                           joints_2d_from=args.joints_2d_from, min_confidence=args.min_confidence,
                           bbox_margin_m=args.bbox_margin, mask_dir=args.mask_dir, mask_fallback=args.mask_fallback,
                           skip_missing_masks=args.skip_missing_masks)
        if not args.subject.is_dir():  # else "annots.npy: missing" under a folder that is not there either
            raise DatasetError(args.subject, "missing: no such subject folder")
        with sigterm_as_interrupt():  # `timeout`, `kill`, a job scheduler: stopped as Ctrl-C stops it
            count = convert_zju(args.subject, args.out, config, split=args.split, shard_size=args.shard_size)
    except (DataConfigError, DatasetError) as e:
        log.error("%s", e)
        return 2
    except KeyboardInterrupt as e:
        if split_replaced(e):
            log.error("stopped by %s once the conversion was done: split %r of %s is the new one", stop_words(e),
                      args.split, args.out)
        else:
            log.error("stopped by %s: split %r of %s is as it was before this conversion", stop_words(e), args.split,
                      args.out)
        return exit_status(e)
    log.info("%s: %d samples converted into split %r of %s", args.subject, count, args.split, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
