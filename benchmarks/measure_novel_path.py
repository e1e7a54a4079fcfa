"""How far a view between the rig's cameras moves when it orbits (``novel_view.path``) rather than takes the line.

For each rig (rig files; the simulator's placements given by ``--sim``, side by side and toed in; and
``--around``: two cameras 3 m from the subject, ``--height`` high (1.3 m; the subject's centre is 0.95 m), aimed
at it from the given angle apart round it, the second aimed ``--aim-off`` cm to its left of it): the angle between
the optical axes, the orbit's pivot (:func:`ghnerf_runtime.novel_view.novel_pivot`, given the subject taken at
the working volume's centre, as on a cold pair) and how far it is from the subject (for ``--around``, the point
the cameras are placed round; else the working volume's centre), where the orbit's halfway camera is (which
way round the view turns), the path ``"auto"`` takes, and at each ``--alphas``: how far the orbit camera's centre is from the
line camera's (mm), the angle between their rotations (degrees; both are slerped, so 0 by construction), how
far the view of the subject turns between them (the angle at the working volume's centre, degrees), both
cameras' distance to that centre (mm), and how far off the orbit camera's optical axis it lies (degrees; 0 in
the middle of the picture; the ends at alpha 0 and 1 are the rig's cameras). Pure geometry, milliseconds; the
cameras as in the rig file (a rig with a camera on its side or upside down turns it upright first in the
estimator; not here). The orbit's pivot is the subject's centre where the axes cross away from it (cameras side
by side toed in past 60 degrees: ``--sim 90``; :func:`ghnerf_runtime.geometry.orbit.orbit_pivot`).

    .venv/bin/python benchmarks/measure_novel_path.py [RIG.json ...] [--sim aimed,60,120] [--around 90,180]
        [--height 1.3] [--aim-off 0] [--alphas 0.25,0.5,0.75]

Default: docs/examples/rig.json alone.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from drivers.sim.placement import RigPlacement  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, intrinsics_from_fov, look_at  # noqa: E402
from ghnerf_runtime.geometry.orbit import axes_angle_deg  # noqa: E402
from ghnerf_runtime.novel_view import interpolate_camera, novel_pivot  # noqa: E402
from ghnerf_runtime.rig_file import load_rig  # noqa: E402


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    cos = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _rotation_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R1.T @ R2) - 1.0) / 2.0, -1.0, 1.0))))


def rig_rows(name: str, rig: Rig, alphas: list[float], aimed_at: np.ndarray | None = None) -> list[str]:
    """The table's lines for one rig (``aimed_at``: the point its cameras are aimed at, default the volume's centre)."""
    a, b = rig.pair
    subject = 0.5 * (rig.volume.min_corner + rig.volume.max_corner)
    aimed_at = subject if aimed_at is None else aimed_at
    pivot = novel_pivot(a, b, "orbit", subject)
    auto = "orbit" if novel_pivot(a, b, "auto", subject) is not None else "line"
    where = "none (line)" if pivot is None else (
        f"({pivot[0]:.3f}, {pivot[1]:.3f}, {pivot[2]:.3f}) m, {np.linalg.norm(pivot - a.center):.3f} / "
        f"{np.linalg.norm(pivot - b.center):.3f} m from the cameras, "
        f"{1e3 * np.linalg.norm(pivot - aimed_at):.1f} mm from the subject; halfway camera at "
        f"({', '.join(f'{v:.3f}' for v in interpolate_camera(a, b, 0.5, pivot=pivot).center)}) m")
    lines = [f"{name}: optical axes {axes_angle_deg(a, b):.3f} deg apart, baseline "
             f"{1e3 * np.linalg.norm(a.center - b.center):.1f} mm; pivot {where}; auto takes the {auto}",
             "| alpha | orbit vs line: centre mm | rotation deg | view of the subject turns deg | "
             "to the subject, line / orbit mm | the subject off the orbit view's axis deg |",
             "|---|---|---|---|---|---|"]
    for alpha in alphas:
        line = interpolate_camera(a, b, alpha)
        orbit = line if pivot is None else interpolate_camera(a, b, alpha, pivot=pivot)
        lines.append(f"| {alpha:g} | {1e3 * np.linalg.norm(orbit.center - line.center):.4f} | "
                     f"{_rotation_deg(orbit.R, line.R):.6f} | "
                     f"{_angle_deg(subject - orbit.center, subject - line.center):.5f} | "
                     f"{1e3 * np.linalg.norm(subject - line.center):.1f} / "
                     f"{1e3 * np.linalg.norm(subject - orbit.center):.1f} | "
                     f"{_angle_deg(subject - orbit.center, orbit.R[2]):.2f} |")
    return lines


AROUND_SUBJECT = np.array([0.0, -0.95, 3.0])


def around_rig(angle_deg: float, height_m: float = 1.3, aim_off_m: float = 0.0) -> Rig:
    """Two 640x480 cameras (80 degrees wide) 3 m from a subject at (0, -0.95, 3), ``angle_deg`` apart round it,
    ``height_m`` above the floor; the second aimed ``aim_off_m`` to its left of the subject (a calibration's
    error, or a camera mounted a little off: its axis passes that far beside the first's)."""
    subject = AROUND_SUBJECT
    K = intrinsics_from_fov(640, 480, 80.0)
    cams = []
    for name, sign in (("left", -1.0), ("right", 1.0)):
        yaw = np.radians(sign * angle_deg / 2.0)
        eye = subject + np.array([3.0 * np.sin(yaw), 0.0, -3.0 * np.cos(yaw)])
        eye[1] = -height_m
        target = subject.copy()
        if name == "right":  # its left: the camera's -x, horizontal across its line of sight
            sight = subject - eye
            target += aim_off_m * np.cross(sight, [0.0, 1.0, 0.0]) / np.linalg.norm(np.cross(sight, [0.0, 1.0, 0.0]))
        cams.append(Camera(name, 640, 480, K, [], *look_at(eye, target)))
    volume = WorkingVolume(subject + [-0.8, -1.15, -0.8], subject + [0.8, 1.0, 0.8])
    return Rig(tuple(cams), volume, f"around-{angle_deg:g}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rigs", nargs="*", default=[str(REPO / "docs" / "examples" / "rig.json")], help="rig files")
    ap.add_argument("--sim", default="", help="comma list of simulator placements: 'aimed' (the default rig, "
                                              "both cameras aimed at the subject) or a convergence in degrees")
    ap.add_argument("--around", default="", help="comma list of angles (degrees) between two cameras round the subject")
    ap.add_argument("--height", type=float, default=1.3, help="--around cameras' height above the floor (m; the "
                                                              "subject's centre is at 0.95)")
    ap.add_argument("--aim-off", type=float, default=0.0, help="--around: the second camera aimed this many cm to "
                                                               "its left of the subject")
    ap.add_argument("--alphas", default="0.25,0.5,0.75", help="comma list of positions between the cameras")
    args = ap.parse_args(argv)
    alphas = [float(v) for v in args.alphas.split(",") if v]
    rigs = [(str(Path(p).resolve().relative_to(REPO)) if Path(p).resolve().is_relative_to(REPO) else p, load_rig(p))
            for p in args.rigs]
    for spec in (s for s in args.sim.split(",") if s):
        placement = RigPlacement() if spec == "aimed" else RigPlacement(convergence_deg=float(spec))
        rigs.append((f"sim {spec}", placement.build()))
    aimed = {}
    for spec in (s for s in args.around.split(",") if s):
        name = f"around {spec} ({args.height:g} m high, aimed {args.aim_off:g} cm off)"
        rigs.append((name, around_rig(float(spec), args.height, args.aim_off / 100.0)))
        aimed[name] = AROUND_SUBJECT
    for name, rig in rigs:
        print("\n".join(rig_rows(name, rig, alphas, aimed.get(name))) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
