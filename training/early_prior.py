"""``python -m training.early_prior JOB``: the skeleton prior from the pretrained encoder, beside the joint run.

The joint run keeps the pretrained encoder frozen (``freeze_human``), so the keypoint graph that ``make model``
exports after it is the pretraining's encoder (the ``human`` graph of a model built from the run's config with
``human_init`` loaded is the one exported from the finished run, byte for byte but for the weights id each export
stamps: ``training.model_card.graph_sha256``, which leaves the id out, is the same). The prior
learns from that graph alone, so it need not wait for the joint run: on two cores the pipeline trains it at one
thread while the joint run takes the other (``training.pipeline.side_by_side_plan``).

``JOB`` is the JSON file the pipeline writes (``<runs>/<preset>_prior/job.json``):

- ``train_config``: the joint run's train config (as its ``config.json`` will hold it: ``human_init`` set);
- ``data``, ``calib_scenes``: the quantize stage's calibration scenes (the same scenes, so the same int8 graph);
- ``prior_argv``: ``training.skeleton_prior``'s arguments (its ``--model-dir`` is this folder);
- ``request``: what the pipeline's prior stage will compare, less the keypoint graphs' hashes;
- ``threads``: the lane's threads (the export's, and ``prior_argv``'s ``--threads``).

This exports and quantizes the keypoint graph into the job's folder, trains the prior there, and last writes
``request.json`` (the request with those hashes, and the ``human.pt`` it came from). The pipeline's prior stage
takes the prior when the exported model's keypoint graphs have the same hashes and the request is unchanged
(``training.pipeline.adopt_early_prior``); otherwise it trains its own, so a mismatch costs time, never a wrong
prior.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REQUEST_FILE = "request.json"
JOB_FILE = "job.json"


def export_keypoint_graph(train_config: dict, data: str | Path, calib_scenes: int, out_dir: str | Path,
                          graph: str = "human") -> dict[str, Path]:
    """``<graph>.onnx`` and ``<graph>.int8.onnx`` of the model ``train_config`` describes, its encoder loaded from
    ``human_init``, calibrated as the pipeline's quantize stage calibrates (the same scenes and inputs)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset
    from training.export.export import example_inputs, export_graph, trained_frame_padding
    from training.export.quantize import calibration_feeds, quantize_all
    from training.model import GHNeRF
    from training.pipeline import CALIB_RAY_STRIDE, CALIB_RAYS_PER_TARGET, _scene_inputs, calibration_items
    from training.pretrain_human import load_human
    from training.train import build_config

    tc = build_config(train_config)
    if not tc.human_init:
        raise ValueError("the train config has no human_init: there is no pretrained encoder to export")
    # human_init's weights replace every encoder weight model.human.init would give (the joint run's, which may
    # have moved since the pretraining read it); the human graph reads the encoder alone
    model = GHNeRF(tc.model_config(), read_init=False).eval()
    load_human(model, tc.human_init)
    out = Path(out_dir)
    # the contract's frame padding as the export stage will write it from the joint run's checkpoint (the same
    # train config): otherwise the graphs' hashes differ and the pipeline trains the prior again
    padding = trained_frame_padding({"config": train_config})
    fp32 = {graph: export_graph(model, graph, out / f"{graph}.onnx", example_inputs(model), frame_padding=padding)}
    calib_ds = MultiViewDataset(data, "train", TargetConfig())
    # calibrated as the quantize stage calibrates (its constants), so the int8 file comes out the same
    calib = [_scene_inputs(model, item, ray_stride=CALIB_RAY_STRIDE, seed=i)
             for i, item in calibration_items(calib_ds, calib_scenes)]
    int8 = quantize_all(fp32, out, calibration_feeds(model, calib, (graph,), rays_per_target=CALIB_RAYS_PER_TARGET))
    return {f"{graph}.onnx": fp32[graph], f"{graph}.int8.onnx": int8[graph]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.early_prior", description=__doc__.split("\n\n")[0])
    ap.add_argument("job", help=f"the pipeline's {JOB_FILE}")
    args = ap.parse_args(argv)
    import torch

    from training import skeleton_prior as sp
    from training.model_card import graph_sha256, sha256, write_atomic
    from training.pipeline import early_prior_current

    job_path = Path(args.job)
    try:  # a missing, cut or foreign job file: one line naming it (was a traceback)
        job = json.loads(job_path.read_text())
        prior = Path(job["prior_argv"][job["prior_argv"].index("--out") + 1])
        human = Path(job["train_config"]["human_init"])
    except (OSError, ValueError, KeyError, TypeError, IndexError) as e:  # (json's errors are ValueErrors)
        ap.error(f"JOB {job_path}: not a readable {JOB_FILE} of the pipeline ({type(e).__name__}: {e})")
    folder = job_path.parent
    if early_prior_current(folder, job["request"], human):  # a pipeline run again after a stop
        print(f"early prior: {prior} is up to date", file=sys.stderr)
        return 0
    (folder / REQUEST_FILE).unlink(missing_ok=True)  # written last: a stopped job leaves none
    # the lane's share of the cores (onnxruntime's calibration sessions take their own for a few seconds)
    torch.set_num_threads(job["threads"])
    graphs = export_keypoint_graph(job["train_config"], job["data"], job["calib_scenes"], folder)
    request = {**job["request"], "keypoints": {name: graph_sha256(p) for name, p in graphs.items()}}
    if sp.main(job["prior_argv"]) != 0:
        return 1
    # whole or not at all: half a request (a full disk, a stop) was read as no early prior, minutes retrained
    write_atomic(folder / REQUEST_FILE, json.dumps({"request": request, "prior": str(prior),
                                                    "prior_sha256": sha256(prior), "human_sha256": sha256(human)},
                                                   indent=1) + "\n")
    print(f"early prior: {prior} (keypoint graphs {', '.join(graphs)})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
