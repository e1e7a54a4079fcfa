"""What the working volume's near edge costs: the same people filmed by one rig told its volume as written and told
it with the near edge moved back to where a standing person fits the lens (and the far edge pulled in).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_volume_near_edge.py [--model-dir models] [--sequences 6]
        [--frames 10] [--rigs synth,docs/examples/rig.json] [--far 4]

``ghcal solve`` gives every rig ``calibration.level.LEVEL_VOLUME`` (0.5-5 m ahead) unless ``--volume`` is given, and
so did ``ghcal synth`` until session 68 (since, its rig's volume starts 2 m ahead). The runtime's cold start crops
the whole volume projected into each image (docs/runtime.md, "Cold tiles"): a volume starting 0.5 m from the cameras
fills the image and a person shrinks in the model's crop. A 1.8 m person (``rig_file.STANDING_PERSON_M``) nearer
than ``STANDING_PERSON_M * fy / height`` (the lens's vertical view, pinhole, the pair's larger) is never seen whole,
whatever the aim. Per rig (``synth``: ``ghcal synth``'s rig, ``calibration.render.synth_rig()``; ``synth-67``: its
rig until session 68, ``example_rig()``; else a rig file), the rows tell the rig's volume
otherwise: as written; its near edge at that lens distance (never under 0.5 m); at the distance where that person
standing at the volume's x centre is whole in both images, aim and lens model included (where it is within the far
edge); and the lens near edge with the far edge at ``--far``. Every row films the same people: the bench's held-out
sequences (``measure_baseline.run_sequence``, ``bench_scene_in``'s seeds) drawn in the lens-near volume up to
``--far`` (so inside every row's volume; ``--people written``: in the volume as written), each sequence cold, the
runtime's defaults. Cells: the volume's depth range, the cold crop's side and the same standing person's height in
it (for the rig as told) and scores. Session 67 measured it (docs/rig-file.md, "The volume's near edge"): the crop
does not move, the 3 m wide volume filling the image's width from either near edge. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from benchmarks.measure_baseline import in_cold_crop_px, run_sequence, score_cells, standing_person_px  # noqa: E402
from calibration.render import example_rig, synth_rig  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import load_session  # noqa: E402
from ghnerf_runtime.geometry import Rig, WorkingVolume  # noqa: E402
from ghnerf_runtime.preprocess import roi_from_volume  # noqa: E402
from ghnerf_runtime.rig_file import STANDING_PERSON_M, load_rig, person_in_view_share  # noqa: E402

#: The nearest near edge any row gets (``LEVEL_VOLUME``'s own).
MIN_NEAR_M = 0.5
#: Step (metres) of the search for where the standing person is whole in both images.
FIT_STEP_M = 0.05


def lens_fit_m(rig: Rig) -> float:
    """How far ahead a :data:`STANDING_PERSON_M` person first spans no more than the lens's vertical view (pinhole,
    the pair's larger distance), never under :data:`MIN_NEAR_M`."""
    return max(MIN_NEAR_M, max(STANDING_PERSON_M * float(cam.K[1, 1]) / cam.height for cam in rig.pair))


def with_depth(volume: WorkingVolume, near: float, far: float) -> WorkingVolume:
    """``volume`` with its z range (depth ahead) set to ``near``-``far``."""
    lo, hi = volume.min_corner.copy(), volume.max_corner.copy()
    lo[2], hi[2] = near, far
    return WorkingVolume(lo, hi)


def whole_fit_m(rig: Rig) -> float | None:
    """The nearest depth (step :data:`FIT_STEP_M`) at which a person standing at the volume's x centre is whole in
    both images (``person_in_view_share`` 1, aim and lens model included), or None within the far edge."""
    far = float(rig.volume.max_corner[2])
    for z in np.arange(MIN_NEAR_M, far + 1e-9, FIT_STEP_M):
        slab = with_depth(rig.volume, z - 1e-3, z + 1e-3)
        if min(person_in_view_share(cam, slab) for cam in rig.pair) >= 1.0:
            return float(z)
    return None


def told(rig: Rig, volume: WorkingVolume, label: str) -> Rig:
    """``rig``'s cameras told ``volume``, ``label`` after its id (the row's name)."""
    return Rig(rig.cameras, volume, rig_id=f"{rig.rig_id} {label}", metadata=rig.metadata)


def variants(rig: Rig, far_m: float) -> list[Rig]:
    """``rig`` told its volume as written, then the rows of the module's docstring."""
    near_lens = lens_fit_m(rig)
    far = float(rig.volume.max_corner[2])
    rows = [told(rig, rig.volume, "as written"),
            told(rig, with_depth(rig.volume, near_lens, far), "near edge at the lens's fit")]
    whole = whole_fit_m(rig)
    if whole is not None and abs(whole - near_lens) > FIT_STEP_M:
        rows.append(told(rig, with_depth(rig.volume, whole, far), "near edge where the person is whole"))
    if near_lens < far_m < far:
        rows.append(told(rig, with_depth(rig.volume, near_lens, far_m), f"lens near edge, far edge {far_m:g} m"))
    return rows


def crop_cells(rig: Rig, people: WorkingVolume, model_px: int) -> str:
    """The cold crop of ``rig`` as told (its volume projected, ``roi_from_volume``; the pair's larger side, image px)
    and how tall the same standing person (at ``people``'s centre, whatever the rig is told) is in it, in the model's
    ``model_px`` input (the pair's smaller). Not ``measure_baseline.framing_cells``: its person stands at the told
    volume's centre, which moves with the near edge, and would shrink for that alone."""
    crop = max(roi_from_volume(cam, rig.volume).size for cam in rig.pair)
    tall = in_cold_crop_px(rig, [standing_person_px(cam, people) for cam in rig.pair], model_px)
    return f"{crop:.0f} | {tall:.0f}"


def rig_named(name: str) -> Rig:
    """``--rigs``' entry: ``synth`` is ``ghcal synth``'s rig, ``synth-67`` the one it was until session 68 (1.4 m up,
    24 degrees down, 0.5-5 m: what session 67 measured), anything else a rig file."""
    if name == "synth":
        return synth_rig()
    if name == "synth-67":
        return example_rig()
    return load_rig(name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=6)
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--rigs", default="synth,docs/examples/rig.json", help="comma-separated: synth (ghcal synth's "
                                                                           "rig), synth-67 (its session-67 one) or "
                                                                           "rig files")
    ap.add_argument("--far", type=float, default=4.0, help="the far edge of the last row, metres ahead")
    ap.add_argument("--people", choices=("lens", "written"), default="lens",
                    help="the volume the people are drawn in: the lens-near one or the one as written")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision))
    session = load_session(cfg)
    print(f"{args.sequences} held-out-like sequences x {args.frames} frames, {args.precision}, people drawn in each "
          f"rig's {'lens-near' if args.people == 'lens' else 'as-written'} volume, each sequence cold")
    print("| rig, volume told | volume ahead, m | cold crop side, image px | standing person (people's centre) tall "
          "in the cold crop, model px | MPJPE mm | joints found | pairs with no joint |")
    print("|---|---|---|---|---|---|---|")
    for name in (n for n in args.rigs.split(",") if n.strip()):
        rig = rig_named(name)
        people = rig.volume if args.people == "written" else with_depth(
            rig.volume, lens_fit_m(rig), min(args.far, float(rig.volume.max_corner[2])))
        for row in variants(rig, args.far):
            runs = [run_sequence(session, cfg, row, k, args.frames, people=people) for k in range(args.sequences)]
            depth = f"{row.volume.min_corner[2]:.2f}-{row.volume.max_corner[2]:.2f}"
            crop = crop_cells(row, people, session.contract.width)
            print(f"| {name}: {row.rig_id.split(' ', 1)[1]} | {depth} | {crop} | {score_cells(runs)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
