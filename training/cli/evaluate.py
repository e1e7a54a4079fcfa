"""``ghnerf-eval``'s command line (torch-free; ``training.evaluate`` runs it)."""
from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path

from training.cli import doc_of, parse_then_run
from training.run_limits import MAX_THREADS
from ghnerf_runtime.path_check import shown, user_path


@dataclass(frozen=True)
class ModelItem:
    """A ``--model`` item, split once (:func:`split_model_item`) where the parser reads it: whether it is
    ``LABEL=SPEC`` depends on which files exist, so the label and spec read later are the ones the parser checked.

    Attributes:
        text: the item as written, for messages (``--model x=m.json: ...``).
        label: the label it gives, None where it gives none.
        spec: the checkpoint file, graph folder or ``folder#int8`` it names.
    """

    text: str
    label: str | None
    spec: str

    @property
    def path(self) -> str:
        """The checkpoint file or graph folder the item reads (its spec without ``#int8``)."""
        return self.spec.partition("#")[0]

    @property
    def name(self) -> str:
        """The label its scores are kept under: the one it gives, else the spec's file or folder name."""
        return Path(self.spec).stem if self.label is None else self.label


def split_model_item(item: str) -> ModelItem:
    """A ``--model`` item's label and spec. ``LABEL=SPEC`` is split at the first ``=`` only where what comes before
    it is a name (no ``/``) and the whole item is no file or folder there: a path holding ``=``
    (``runs/lr=1e-3/x.pt``) was read as the label ``runs/lr`` and the spec ``1e-3/x.pt``. An explicit label
    (``x=runs/lr=1e-3/x.pt``) always reads the rest as the spec."""
    label, sep, spec = item.partition("=")
    if not sep or "/" in label or _names_a_file(item):
        return ModelItem(item, None, item)
    return ModelItem(item, label, spec)


def _names_a_file(spec: str) -> bool:
    # os.path.exists, not Path.exists: False (not ValueError) for a NUL, which the path check then names
    return os.path.exists(spec.partition("#")[0])


def _model_item(text: str) -> ModelItem:
    """A ``--model`` item (:func:`split_model_item`) with no empty label whose file or folder (:attr:`ModelItem.path`)
    is a path a file can have: a name past 255 bytes there raised ``ENAMETOOLONG`` from the loader (a traceback).
    Here, not in ``training.evaluate``, which loads torch, so that the parser checks it."""
    item = split_model_item(text)
    if item.label == "":
        # "=x.pt" was scored under the label "", a key no reader of the JSON expects
        raise argparse.ArgumentTypeError(f"{shown(text)}: the LABEL before '=' is empty; write LABEL=SPEC or the "
                                         "spec alone")
    user_path(item.path)
    return item


def build_parser() -> argparse.ArgumentParser:
    doc = doc_of("training.evaluate")
    ap = argparse.ArgumentParser(prog="ghnerf-eval", description=doc.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=doc)
    ap.add_argument("--data", type=user_path, default="data/edge128")
    ap.add_argument("--split", default="val", help="held-out split (default val: unseen bodies, motions, rigs)")
    ap.add_argument("--model", action="append", required=True, metavar="LABEL=SPEC", type=_model_item,
                    help="x.pt (torch checkpoint) | folder (ONNX fp32) | folder#int8; repeatable, each "
                         "LABEL its own (without LABEL=, the file's or folder's name); a LABEL holds no '/', and "
                         "an item naming a file or folder is read whole, so runs/lr=1e-3/x.pt is a path")
    ap.add_argument("--limit", type=int, default=0, help="first N scenes only (0: all)")
    ap.add_argument("--no-novel", action="store_true", help="skip the novel-view PSNR/SSIM")
    ap.add_argument("--threads", type=int, default=2, help=f"torch and onnxruntime threads (1 to {MAX_THREADS})")
    ap.add_argument("--out", type=user_path, help="write the JSON here (also printed)")
    return ap


def main(argv: list[str] | None = None) -> int:
    """The ``ghnerf-eval`` console script."""
    return parse_then_run(build_parser, "training.evaluate", argv)


if __name__ == "__main__":  # `python -m training.cli.evaluate`, the module pyproject names: it ran nothing, exit 0
    raise SystemExit(main())
