"""``python -m training.learnt_fill``'s command line (torch-free; ``training.learnt_fill`` runs it)."""
from __future__ import annotations

import argparse
from pathlib import Path

from training.cli import at_least, doc_of, parse_then_run


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m training.learnt_fill",  # not "learnt_fill.py"
                                 description=doc_of("training.learnt_fill").split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("cache", help="compute a split's fill features (training.fill_features)")
    c.add_argument("--data", required=True)
    c.add_argument("--split", default="val")
    c.add_argument("--limit", type=at_least(0), default=0, help="first N scenes (0: all)")
    c.add_argument("--workers", type=at_least(1), default=2)
    c.add_argument("--model", default=None, metavar="CKPT",
                   help="a GHNeRF checkpoint whose geometry and picture replace the truth's (default: the truth)")
    c.add_argument("--joints", default=None, metavar="NPZ",
                   help="with --model: the device's joints of the split (python -m training.device_joints), whose "
                        "body proxy (training.body_proxy) is the geometry")
    c.add_argument("--no-relit", action="store_true",
                   help="skip the light fit and the relit fill (docs/training.md, \"The painter and the fog\"): what the "
                        "runtime's painter (net.relit_input=false) reads is unchanged")
    c.add_argument("--out", required=True, type=Path)
    t = sub.add_parser("train", help="train the fill net and score it on the held-out cache")
    t.add_argument("--train-cache", required=True, type=Path)
    t.add_argument("--val-cache", required=True, type=Path)
    t.add_argument("--out", required=True, type=Path, help="folder for fill_net.pt and score.md")
    t.add_argument("--train-views", type=at_least(0), default=0, help="train on the cache's first N views (0: all)")
    t.add_argument("--device", default=None, choices=("auto", "cpu", "cuda"), help="auto (default), cpu or cuda")
    t.add_argument("--threads", type=at_least(0), default=0, help="torch CPU threads (0: torch's default)")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="FillTrainConfig override (steps, batch, lr, ..., net.width, net.levels)")
    s = sub.add_parser("score", help="score a trained fill net on a held-out cache")
    s.add_argument("--val-cache", required=True, type=Path)
    s.add_argument("--net", required=True, type=Path, action="append",
                   help="a fill_net.pt; given more than once, the nets' mean picture is scored (an ensemble)")
    s.add_argument("--flip-test", action="store_true",
                   help="average each net's picture with its picture of the mirrored views")
    s.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    e = sub.add_parser("export", help="the runtime's painter: novel_painter.onnx (and its figures) from a fill net")
    e.add_argument("--net", required=True, type=Path, help="a fill_net.pt trained with net.relit_input=false, "
                                                           "net.shown_input=true")
    e.add_argument("--out", required=True, type=Path, help="the .onnx to write (models/ghnerf/novel_painter.onnx)")
    e.add_argument("--val-cache", type=Path, default=None, help="check onnxruntime against torch on its first views")
    e.add_argument("--calib-cache", type=Path, default=None,
                   help="also write the int8 file (<out stem>.int8.onnx), calibrated on this cache's first views "
                        "(the training cache)")
    e.add_argument("--card-dir", type=Path, default=None, help="record the painter in this model card (models/)")
    return ap


def main(argv: list[str] | None = None) -> int:
    return parse_then_run(build_parser, "training.learnt_fill", argv)


if __name__ == "__main__":  # `python -m training.cli.learnt_fill`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
