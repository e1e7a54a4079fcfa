"""``python -m training.export``: export a preset (or checkpoint) to ONNX, quantize, check parity, time it.

Example::

    python -m training.export --preset edge128 --out out/edge128 --int8 --bench --report out/edge128/report.json

The graphs are written and checked in ``OUT.staging`` and moved into ``OUT`` only once the parity checks pass
(or with ``--no-parity-check``): a failure leaves ``OUT`` as it was (exit 1) and the rejected files in
``OUT.staging``. Moving in removes the ``<graph>.int8.onnx`` of every replaced fp32 graph (unless ``--int8``
makes a new one) and sets aside a ``model_card.json`` (in ``OUT`` or its parent) whose hashes no longer match,
as ``model_card.stale.json`` (a warning says so).

Without a checkpoint the weights are random (useful for latency and plumbing, not accuracy). The
calibration frames are random images on a synthetic rig unless ``--calib-npz`` gives real frames
(``images`` array ``(F, 2, 3, H, W)`` float RGB in [0, 1] at the model's resolution, as the runtime feeds it);
a file that holds anything else is refused before the export, exit 2 (``training.export.calibration``).
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from ghnerf_runtime.cli.output_path import existing_ancestor, ready_output_arg, unwritable_reason
from ghnerf_runtime.contract import GRAPH_NAMES
from training.configs import PRESETS, preset
from training.export.calibration import MIN_FRAMES
from training.export.opsets import DEFAULT_OPSET, MAX_OPSET, MIN_OPSET, opset_problem
from training.model_card import strict_json, write_atomic

if TYPE_CHECKING:  # torch and the modules on it load in main, after the arguments (--help without torch's 3 s)
    from training.export.export import ExampleInputs
    from training.model import GHNeRF

log = logging.getLogger("training.export")

#: Random calibration frames without --calib-frames (and without --calib-npz, whose file gives its own).
DEFAULT_CALIB_FRAMES = 8

#: Per-graph timing scenarios: (graph, label, targets, ray stride, points); targets 2 = the two sources.
SCENARIOS = (
    ("encoder", "S=2", 2, None, 0),
    ("human", "S=2 (encoder heatmaps only)", 2, None, 0),
    ("volume", "B=2 (source views)", 2, None, 0),
    ("render_heat", "B=2 R=2x(H/4)^2", 2, 4, 0),
    ("volume", "B=1 (novel view)", 1, None, 0),
    ("render_rgb", "B=1 R=H^2", 1, 1, 0),
    ("render_rgb", "B=1 R=(H/2)^2", 1, 2, 0),
    ("render", "B=1 R=H^2", 1, 1, 0),
    ("query", "B=2 N=16^3", 2, None, 4096),
)


def _inputs(model: GHNeRF, targets: int, stride: int | None, points: int) -> ExampleInputs:
    """Example inputs with ``targets`` targets: 2 = both sources, 1 = one novel camera."""
    from training.export.export import ExampleInputs, example_inputs  # noqa: PLC0415

    if targets == 2:
        return example_inputs(model, targets=2, ray_stride=stride, points=max(points, 1))
    ex = example_inputs(model, targets=3, ray_stride=stride, points=max(points, 1))
    per_target = {"tgt_K_inv", "tgt_c2w", "tgt_P", "near_far", "ray_uv", "points", "volume", "depth_stats"}
    return ExampleInputs({k: (v[2:3] if k in per_target else v) for k, v in ex.tensors.items()})


def time_graphs(model: GHNeRF, paths: dict[str, Path], threads: int = 2, repeats: int = 30) -> list[dict]:
    from training.export.parity import benchmark, make_session  # noqa: PLC0415

    contract = model.contract()
    rows = []
    cache: dict = {}
    for graph, label, targets, stride, points in SCENARIOS:
        if graph not in paths:
            continue
        key = (targets, stride, points)
        if key not in cache:
            cache[key] = _inputs(model, targets, stride, points)
        sess = make_session(paths[graph], threads, spin=True)  # one graph at a time: spinning helps
        t = benchmark(sess, cache[key].numpy(contract.graph(graph)), repeats=repeats)
        rows.append({"graph": graph, "case": label, **t})
    return rows


def build_parser() -> argparse.ArgumentParser:
    """The command line (torch-free: ``--help`` and usage errors come before torch loads)."""
    ap = argparse.ArgumentParser(prog="python -m training.export", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="edge128", choices=sorted(PRESETS))
    ap.add_argument("--checkpoint", help="trainer checkpoint or weights file (.pt); its stored model config "
                    "overrides --preset; default: random weights")
    ap.add_argument("--out", required=True, help="output folder for <graph>.onnx / <graph>.int8.onnx")
    ap.add_argument("--graphs", default="", help=f"comma-separated subset of {','.join(GRAPH_NAMES)} "
                    "(default: every graph the model has)")
    ap.add_argument("--opset", type=int, default=DEFAULT_OPSET,
                    help=f"ONNX opset of the graphs, {MIN_OPSET} to {MAX_OPSET} (training.export.opsets; default "
                         f"{DEFAULT_OPSET})")
    ap.add_argument("--int8", action="store_true", help="also write static int8 QDQ graphs")
    ap.add_argument("--calib-frames", type=int, default=None,
                    help=f"random calibration frames (no --calib-npz), at least {MIN_FRAMES} (default "
                         f"{DEFAULT_CALIB_FRAMES})")
    ap.add_argument("--calib-npz", help="npz with images (F, 2, 3, H, W) float RGB in [0, 1] at the model's "
                    f"resolution, at least {MIN_FRAMES} frame pairs, no view uniform (checked before the export)")
    ap.add_argument("--bench", action="store_true", help="time every graph (fp32 and int8)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--report", help="write the figures as JSON here")
    ap.add_argument("--no-parity-check", action="store_true",
                    help="exit 0 even when onnxruntime strays from torch, or int8 from fp32, beyond "
                         "training.export.parity's bounds")
    return ap


def model_folder_place_problem(out: Path) -> str | None:
    """Why the folder that holds ``out`` cannot take ``out`` and ``<out>.staging``, where the graphs are written
    first (None: it can). An --out under a file or on a read-only or virtual file system was a traceback after the
    model was built, and under a file it blamed a "cut-short move" that never happened."""
    parent = Path(os.path.abspath(out)).parent
    found = existing_ancestor(parent)
    if not found.is_dir():
        return f"{found} is a file, not a folder"
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        return f"cannot make the folder {parent} ({e.strerror or e})"
    reason = unwritable_reason(parent)
    if reason is not None:
        return f"the folder {parent} is not writable ({reason}); {out.name} and {out.name}.staging are made there"
    return None


def unfinished_run_words(path: str, checkpoint: object) -> str | None:
    """What to warn of a trainer checkpoint written before its run's last step (a run stopped by Ctrl-C, a
    SIGTERM or ``max_minutes``, or a ``ckpt_*.pt`` of a longer run); None for a finished run's or a weights file
    that records no run. Exported without a word, its graphs sat in a model folder as if the run had ended."""
    if not isinstance(checkpoint, dict):
        return None
    step, config = checkpoint.get("step"), checkpoint.get("config")
    iterations = config.get("iterations") if isinstance(config, dict) else None
    if not (isinstance(step, int) and isinstance(iterations, int)) or step >= iterations:
        return None
    return (f"{path}: step {step} of its run's {iterations} iterations: the run has not finished (`--resume` "
            "continues it); exporting its weights as they are")


def _graph_files(out: Path, graphs: Iterable[str]) -> list[Path]:
    """The fp32 and int8 files of ``graphs`` that ``out`` holds."""
    return [out / f"{graph}{suffix}" for graph in graphs for suffix in (".onnx", ".int8.onnx")
            if (out / f"{graph}{suffix}").is_file()]


def graph_files_left(out: Path, written: tuple[str, ...]) -> list[Path]:
    """The graph files of ``out`` an export of the graphs ``written`` leaves in place: those of other graphs (a
    ``--graphs`` subset, or graphs this model has not), fp32 and int8."""
    return _graph_files(out, (graph for graph in GRAPH_NAMES if graph not in written))


def file_weights_id(path: Path) -> str | None:
    """The weights id a graph file carries (``ghnerf.weights_id``); None when it has none or cannot be read (the
    runtime names such a file when it loads the folder)."""
    import onnx  # noqa: PLC0415 - with torch, after the arguments
    from google.protobuf.message import DecodeError  # noqa: PLC0415

    from ghnerf_runtime.contract import ContractError, weights_id_of  # noqa: PLC0415

    try:
        props = {p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props}
        return weights_id_of(props)
    except (OSError, DecodeError, ContractError):  # truncated, damaged: nothing to compare
        return None


def mixed_folder_problem(out: Path, written: tuple[str, ...], weights: str) -> str | None:
    """Why exporting the graphs ``written`` of the weights ``weights`` into ``out`` would leave a folder of two
    models (None: it would not): ``out`` keeps graph files of other weights beside them, which the runtime refuses
    to load as one model; the folder's working graphs were replaced by then. Files without a weights id (exported
    before there were ids) cannot be compared and are left to the runtime's warning."""
    others = _of_other_weights(graph_files_left(out, written), weights)
    if not others:
        return None
    names = ", ".join(f.name for f, _ in others)
    return (f"{names} (weights id {others[0][1][:16]}...) stay in {out} beside this export's "
            f"{', '.join(written)} (weights id {weights[:16]}...): the folder would hold two models, which the "
            "runtime refuses to load; export every graph of the model (no --graphs) or give another --out")


def other_weights_replaced(out: Path, written: tuple[str, ...], weights: str) -> list[tuple[Path, str]]:
    """The graph files of ``out`` this export replaces (or drops, their int8) that hold other weights than
    ``weights``, with their ids: another model, which the move replaces with no more than an INFO line."""
    return _of_other_weights(_graph_files(out, written), weights)


def _of_other_weights(files: list[Path], weights: str) -> list[tuple[Path, str]]:
    """Those of ``files`` whose weights id is known and not ``weights``, with their ids."""
    return [(f, wid) for f in files if (wid := file_weights_id(f)) not in (None, weights)]


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    # what torch raised a traceback for, after the export into OUT.staging (the frames) or before it (the threads,
    # the opset: "Unsupported onnx_opset_version" or an unsupported grid_sampler, after loading the model)
    if problem := opset_problem(args.opset):
        ap.error(f"--opset: {problem}, got {args.opset}")
    if args.threads < 1:
        ap.error(f"--threads: must be at least 1, got {args.threads}")
    if args.calib_frames is not None and args.calib_frames < MIN_FRAMES:  # the floor --calib-npz has: one or two
        # frames' ranges are one scene's
        ap.error(f"--calib-frames: must be at least {MIN_FRAMES} (calibration.MIN_FRAMES, as for --calib-npz), "
                 f"got {args.calib_frames}")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        ap.error(f"--out {args.out}: is a file; give the model folder")
    if problem := model_folder_place_problem(Path(args.out)):
        ap.error(f"--out {args.out}: {problem}")
    if args.calib_npz and not args.int8:  # calibration frames are only read for int8: ignoring them misleads
        ap.error("--calib-npz calibrates the int8 graphs: give --int8 with it")
    if args.calib_frames is not None and not args.int8:
        ap.error("--calib-frames counts the int8 graphs' random calibration frames: give --int8 with it")
    if args.calib_frames is not None and args.calib_npz:  # the file's frames were taken, all of them, without a word
        ap.error(f"--calib-frames {args.calib_frames} counts random calibration frames, which --calib-npz replaces "
                 "with every frame pair of its file: give one of them")
    if args.calib_frames is None:
        args.calib_frames = DEFAULT_CALIB_FRAMES
    if args.report:  # written after the export, parity, int8 and timings: its place is settled first
        args.report = ready_output_arg(ap, args.report, "--report")
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    import torch  # noqa: PLC0415 - after the arguments: torch takes seconds to load

    from training.export.calibration import CalibrationDataError, load_calibration_npz  # noqa: PLC0415
    from training.export.parity import ParityError  # noqa: PLC0415
    from training.export.staging import drop_stale_int8, move_into, rejected, staging_dir  # noqa: PLC0415
    from training.model import GHNeRF  # noqa: PLC0415

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)

    frame_padding = "none"  # random weights learnt nothing of the frame's edge
    if args.checkpoint:
        from ghnerf_runtime.contract import ContractError
        from training.export.export import trained_frame_padding
        from training.model.config import ConfigError
        from training.train import load_model  # lazy: the trainer is not needed for random weights

        try:
            model, ck = load_model(args.checkpoint, default_config=preset(args.preset))
            frame_padding = trained_frame_padding(ck)  # into the contract: the runtime pads crops as trained
            if words := unfinished_run_words(args.checkpoint, ck):
                log.warning(words)
        except ConfigError as e:  # a damaged or foreign file, named
            print(f"python -m training.export: error: {e}", file=sys.stderr)
            return 2
        except ContractError as e:  # a padding record that is none the contract knows, keyed
            print(f"python -m training.export: error: {args.checkpoint}: {e}", file=sys.stderr)
            return 2
    else:
        log.warning("no --checkpoint: exporting random weights (to test the export, not to run)")
        model = GHNeRF(preset(args.preset)).eval()
    has = model.contract(opset=args.opset).graph_names
    graphs = tuple(g for g in args.graphs.split(",") if g) or has
    if unknown := [g for g in graphs if g not in has]:
        ap.error(f"--graphs: {', '.join(unknown)} not among this model's graphs ({', '.join(has)})")
    from training.export.export import weights_id  # noqa: PLC0415

    weights = weights_id(model)
    if problem := mixed_folder_problem(Path(args.out), graphs, weights):  # before anything is written
        print(f"python -m training.export: error: --out {args.out}: {problem}", file=sys.stderr)
        return 2
    replacing = other_weights_replaced(Path(args.out), graphs, weights)  # said once they are replaced
    calib_frames = None
    if args.int8 and args.calib_npz:  # checked before anything is written: a wrong file fails in a second
        try:
            calib_frames = load_calibration_npz(args.calib_npz, model.contract(opset=args.opset))
        except CalibrationDataError as e:
            print(f"python -m training.export: error: --calib-npz {e}", file=sys.stderr)
            return 2
    out = Path(args.out)
    # everything is written and checked in OUT.staging; OUT (perhaps a live model folder) changes only once the
    # parity checks pass (training.export.staging)
    staging = staging_dir(out)
    try:
        fp32, int8 = _export_and_check(args, model, graphs, staging, calib_frames, frame_padding)
    except ParityError as e:
        try:
            rejected(out, staging, e)
        except ParityError as said:
            print(f"python -m training.export: {said}", file=sys.stderr)
        return 1
    except BaseException as e:
        rejected(out, staging, e)
        raise
    removed = drop_stale_int8(out, fp32)
    move_into(staging, out, [*fp32.values(), *int8.values()], removed)
    log.info("moved %d graph(s) into %s", len(fp32) + len(int8), out)
    if replacing:
        log.warning("%s held another model: its %s (weights id %s...) were replaced by this export's (weights id "
                    "%s...)", out, ", ".join(f.name for f, _ in replacing), replacing[0][1][:16], weights[:16])
    return 0


def _export_and_check(args: argparse.Namespace, model: GHNeRF, graphs: tuple[str, ...], staging: Path,
                      calib_frames: list[np.ndarray] | None = None,
                      frame_padding: str = "none") -> tuple[dict[str, Path], dict[str, Path]]:
    """Export (and quantize, time) into ``staging``, print and write the report, then check the parity (unless
    ``--no-parity-check``): a :class:`ParityError` names the graph. ``calib_frames``: the checked ``--calib-npz``
    frames (None: random ones); ``frame_padding``: the contract's (the checkpoint's training padding). Returns
    the staged fp32 and int8 files."""
    import torch  # noqa: PLC0415

    from training.export.export import example_inputs, export_all  # noqa: PLC0415
    from training.export.parity import check_fp32_parity, check_int8_parity, int8_vs_fp32, torch_vs_ort  # noqa: PLC0415
    from training.export.quantize import calibration_feeds, quantize_all  # noqa: PLC0415

    report: dict = {"preset": args.preset, "parameters": model.parameter_counts(),
                    "contract": {"resolution": f"{model.config.width}x{model.config.height}",
                                 "frame_padding": frame_padding}}
    fp32 = export_all(model, staging, graphs=graphs, opset=args.opset, inputs=example_inputs(model),
                      frame_padding=frame_padding)
    report["fp32_parity"] = torch_vs_ort(model, fp32, example_inputs(model, targets=3, ray_stride=2, seed=1))
    int8 = {}
    if args.int8:
        H, W = model.config.height, model.config.width
        if calib_frames is not None:
            frames = [torch.from_numpy(f) for f in calib_frames]
        else:
            log.warning("no --calib-npz: calibrating int8 on random images; a trained model wants real frames "
                        "(make model calibrates on training scenes)")
            g = torch.Generator().manual_seed(1)
            frames = [torch.rand(2, 3, H, W, generator=g) for _ in range(args.calib_frames)]
        calib = [example_inputs(model, images=f, targets=3, ray_stride=2, seed=i) for i, f in enumerate(frames)]
        int8 = quantize_all(fp32, staging, calibration_feeds(model, calib, graphs, rays_per_target=2048))
        report["int8_vs_fp32"] = int8_vs_fp32(fp32, int8, model.contract(),
                                              example_inputs(model, targets=2, seed=7))
    if args.bench:
        report["latency_fp32"] = time_graphs(model, fp32, args.threads)
        if int8:
            report["latency_int8"] = time_graphs(model, int8, args.threads)
        report["load_average"] = os.getloadavg()
    text = strict_json(report, indent=2)  # a broken model's NaN parity figures as null, not a bare NaN
    print(text)  # first: the figures reach the terminal whatever happens to the file
    if args.report:
        write_atomic(args.report, text)
    if not args.no_parity_check:
        check_fp32_parity(report["fp32_parity"], f"{staging}/")
        if int8:
            check_int8_parity(report["int8_vs_fp32"], f"{staging}/")
    return fp32, int8


if __name__ == "__main__":
    sys.exit(main())
