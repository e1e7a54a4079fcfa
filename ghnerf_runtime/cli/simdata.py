"""Simulator data for the runtime's tools: held-out-like sequences (rendered once, cached) and
accuracy bookkeeping; and the reproducible example pair of ``docs/runtime.md``.

A *tool* module: it imports ``drivers`` (the simulator), lazily, inside the functions that
render. The runtime library (session, estimator, ...) never imports it.

Held-out-like sequences
    Each sequence is one random rig and one random scene, drawn as the ``val`` split draws them
    (``training/data/splits.py``): unseen bodies, rooms, light and sensors (scene seeds
    ``3 * 2**50 + k``, a range no dataset split uses), source baselines in the held-out band
    0.85-1.05 m, and the held-out motions ``jumping_jacks`` and ``reach`` (``seen_motions``
    uses the training motions instead). Unlike the training samples (single instants), a
    sequence is ``frames`` consecutive instants at ``fps``, so tracking is exercised.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.metrics import acceleration_error, left_right_swaps, mpjpe, mpjpe_by_visibility, pck, \
    visibility_class
from ghnerf_runtime.rig_file import dumps_rig, loads_rig, save_rig

log = logging.getLogger(__name__)

__all__ = ["SEED_BASE", "HELD_OUT_MOTIONS", "SEEN_MOTIONS", "Sequence", "load_sequences", "bench_rig_and_scene",
           "render_frames", "Accuracy", "default_cache_dir", "SEQUENCE_CACHE_HELP", "write_sim_example",
           "percentiles", "depth_per_disparity_px"]

#: Scene seeds of the bench sequences: 3 * 2**50 + k, outside every dataset split's range.
SEED_BASE = 3 * 2 ** 50
HELD_OUT_MOTIONS = ("jumping_jacks", "reach")
SEEN_MOTIONS = ("stand", "walk", "wave", "squat", "arm_circles", "turn")
HELD_OUT_BASELINE_M = (0.85, 1.05)
#: Bump when the rendering recipe changes (invalidates caches).
RECIPE_VERSION = 1


def default_cache_dir() -> Path:
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "ghnerf-bench"


#: The ``--cache`` help of every script that renders the bench's sequences (``load_sequences``): the default is
#: :func:`default_cache_dir`'s, which follows ``XDG_CACHE_HOME`` (the help said ``~/.cache`` only).
SEQUENCE_CACHE_HELP = ("sequence cache folder (default $XDG_CACHE_HOME/ghnerf-bench when XDG_CACHE_HOME is set, "
                       "else ~/.cache/ghnerf-bench; 'off': render into memory, cache nothing)")


# ------------------------------------------------------------------ sequences
@dataclass(frozen=True, eq=False)
class Sequence:
    """One rendered sequence.

    Attributes:
        rig: the sequence's rig.
        images: ``(F, 2, H, W, 3)`` uint8 BGR.
        joints_3d: ``(F, 25, 3)`` truth, rig frame, metres.
        joints_2d: ``(F, 2, 25, 2)`` truth in the (distorted) images.
        visible: ``(F, 2, 25)`` bool (in the image, in front, not occluded by the body).
        info: motion, seed, baseline.
    """

    rig: Rig
    images: np.ndarray
    joints_3d: np.ndarray
    joints_2d: np.ndarray
    visible: np.ndarray
    info: dict

    def __len__(self) -> int:
        return len(self.images)


def bench_rig_and_scene(k: int, width: int = 640, height: int = 480, motions: tuple[str, ...] = HELD_OUT_MOTIONS,
                        seed_base: int = SEED_BASE):
    """The rig, scene, first instant and rig placement of bench sequence ``k`` (what :func:`load_sequences`
    renders), for tools that render the same scenes otherwise (``benchmarks/measure_lying_rendered.py``)."""
    from drivers.sim import RigPlacement, random_scene  # tool only: the runtime library never imports drivers

    seed = seed_base + k
    rng = np.random.default_rng([seed, 7])
    base = RigPlacement.random(rng, width=width, height=height)
    placement = replace(base, baseline_m=float(rng.uniform(*HELD_OUT_BASELINE_M)))
    rig = placement.build(rig_id=f"bench-{k}")
    scene = random_scene(seed, volume=rig.volume, motions=motions)
    t0 = float(rng.uniform(0.0, scene.period_s))
    return rig, scene, t0, placement


def _render_sequence(k: int, frames: int, fps: float, width: int, height: int, motions: tuple[str, ...],
                     seed_base: int) -> Sequence:
    rig, scene, t0, placement = bench_rig_and_scene(k, width, height, motions, seed_base)
    info = {"index": k, "scene_seed": seed_base + k, "motion": str(scene.config.motion),
            "baseline_m": placement.baseline_m, "distance_m": placement.distance_m, "fps": fps, "t0": t0}
    return render_frames(rig, scene, t0, frames, fps, info)


def render_frames(rig, scene, t0: float, frames: int, fps: float, info: dict) -> Sequence:
    """``frames`` pairs of ``scene`` (a ``drivers.sim.SimScene``) filmed by ``rig.pair`` from scene time ``t0`` at
    ``fps``, with their truth: a bench sequence's frames, or those of a tool that changes its rig or scene
    (``benchmarks/measure_exchanged_cameras.py``)."""
    h, w = rig.pair[0].height, rig.pair[0].width
    imgs = np.empty((frames, 2, h, w, 3), np.uint8)
    j3 = np.empty((frames, 25, 3))
    j2 = np.empty((frames, 2, 25, 2))
    vis = np.empty((frames, 2, 25), bool)
    for i in range(frames):
        t = t0 + i / fps
        for c, cam in enumerate(rig.pair):
            img, truth = scene.render(cam, t)
            imgs[i, c] = img
            j2[i, c] = truth.joints_2d
            vis[i, c] = truth.visible
        j3[i] = scene.joints_3d(t)
    return Sequence(rig, imgs, j3, j2, vis, info)


def sequence_cache_folder(num_sequences: int, frames: int, *, fps: float = 30.0, width: int = 640,
                          height: int = 480, seen_motions: bool = False, cache_dir: str | os.PathLike | None = None,
                          seed_base: int = SEED_BASE) -> Path | None:
    """Where :func:`load_sequences` caches these sequences (None for ``cache_dir="off"``)."""
    motions = SEEN_MOTIONS if seen_motions else HELD_OUT_MOTIONS
    key = json.dumps([RECIPE_VERSION, num_sequences, frames, fps, width, height, motions, seed_base])
    digest = hashlib.sha1(key.encode()).hexdigest()[:12]
    return None if str(cache_dir) == "off" else Path(cache_dir or default_cache_dir()) / f"seq-{digest}"


def sequences_to_render(folder: Path | None, num_sequences: int) -> int:
    """How many of the sequences :func:`load_sequences` would render (all of them without a cache)."""
    if folder is None:
        return num_sequences
    return sum(not (folder / f"{k:03d}" / "done").is_file() for k in range(num_sequences))


def sequence_bytes(frames: int, width: int = 640, height: int = 480) -> int:
    """One sequence's images (two cameras, 8-bit RGB): what it takes on disk, or in memory without a cache."""
    return frames * 2 * height * width * 3


def load_sequences(num_sequences: int = 10, frames: int = 30, *, fps: float = 30.0, width: int = 640,
                   height: int = 480, seen_motions: bool = False, cache_dir: str | os.PathLike | None = None,
                   seed_base: int = SEED_BASE) -> list[Sequence]:
    """Held-out-like sequences, rendered on first use and cached (``cache_dir``, default :func:`default_cache_dir`:
    ``$XDG_CACHE_HOME/ghnerf-bench``, else ``~/.cache/ghnerf-bench``; ``"off"`` disables). About 0.03-0.04 s a pair to render on session 63's host (``-v`` logs each sequence's time)."""
    motions = SEEN_MOTIONS if seen_motions else HELD_OUT_MOTIONS
    folder = sequence_cache_folder(num_sequences, frames, fps=fps, width=width, height=height,
                                   seen_motions=seen_motions, cache_dir=cache_dir, seed_base=seed_base)
    out = []
    for k in range(num_sequences):
        path = folder / f"{k:03d}" if folder else None
        if path is not None and (path / "done").is_file():
            out.append(_load_cached_sequence(path))
            continue
        t = time.perf_counter()
        seq = _render_sequence(k, frames, fps, width, height, motions, seed_base)
        log.info("rendered sequence %d/%d (%s, %d frames) in %.1f s", k + 1, num_sequences, seq.info["motion"],
                 frames, time.perf_counter() - t)
        if path is not None:
            path.mkdir(parents=True, exist_ok=True)
            for n in ("images", "joints_3d", "joints_2d", "visible"):
                np.save(path / f"{n}.npy", getattr(seq, n))
            (path / "rig.json").write_text(dumps_rig(seq.rig))
            (path / "info.json").write_text(json.dumps(seq.info))
            (path / "done").write_text("ok")
            # read back mapped, not held: a long run's images stay on disk, not all in memory at once
            seq = _load_cached_sequence(path)
        out.append(seq)
    return out


def _load_cached_sequence(path: Path) -> Sequence:
    """A cached sequence, its images memory-mapped (read from disk as each pair runs)."""
    arrays = {n: np.load(path / f"{n}.npy", mmap_mode="r") for n in ("images", "joints_3d", "joints_2d", "visible")}
    rig = loads_rig((path / "rig.json").read_text())
    return Sequence(rig, arrays["images"], np.asarray(arrays["joints_3d"]), np.asarray(arrays["joints_2d"]),
                    np.asarray(arrays["visible"]), json.loads((path / "info.json").read_text()))


# ------------------------------------------------------------------ accuracy
class Accuracy:
    """Pools predictions over pairs; PCK@0.2 per camera image and MPJPE (docs/metrics.md).

    ``summary()`` also splits the 3D figures between tracked pairs and cold starts (crop and
    sweep from the working volume), which behave differently, and where every pair says which frame
    of which stream it is, gives the jitter of the 3D joints (``metrics.acceleration_error``, over
    runs of consecutive frames).
    """

    def __init__(self) -> None:
        self.p2, self.t2, self.v2, self.pv2 = [], [], [], []
        self.p3, self.t3, self.pv3, self.c3, self.tracked = [], [], [], [], []
        self.vis3: list[np.ndarray | None] = []  # (C, 25) per pair, for the MPJPE by visibility
        self.frames: list[tuple[object, int] | None] = []  # (stream, frame number) per pair, for the jitter

    def add(self, result, seq: Sequence, i: int) -> None:
        self.add_truth(result, seq.joints_3d[i], seq.joints_2d[i], seq.visible[i], frame=(id(seq), i))

    def add_truth(self, result, joints_3d, joints_2d=None, visible=None, frame: tuple[object, int] | None = None
                  ) -> None:
        """One pair against its truth: ``(25, 3)`` joints and, optionally, per camera (rig order)
        ``(C, 25, 2)`` pixels with ``(C, 25)`` visibility for the 2D score; ``frame``: which stream
        (any key) and frame number the pair is, for the jitter (pairs of one stream in order)."""
        if joints_2d is not None:
            for c, name in enumerate(result.joints_2d):
                self.p2.append(result.joints_2d[name])
                self.t2.append(joints_2d[c])
                self.v2.append(visible[c])
                self.pv2.append(~result.missing_2d[name])
        self.p3.append(result.joints_3d)
        self.t3.append(joints_3d)
        self.pv3.append(~result.missing)
        self.c3.append(result.confidence)
        self.tracked.append(bool(result.tracked))
        self.vis3.append(None if visible is None else np.asarray(visible, bool))
        self.frames.append(frame)

    def _swaps(self, p2: np.ndarray, t2: np.ndarray, v2: np.ndarray, pv2: np.ndarray) -> dict:
        """Left/right swaps of the 2D joints (``metrics.left_right_swaps``): the share of evaluated pairs
        swapped in each view, and of the pairs evaluated in every view, the share swapped in all of them
        (a swap triangulation cannot see: both views agree). The arguments hold one row per view of
        every pair, views fastest."""
        views = len(p2) // len(self.p3)
        shape = (len(self.p3), views)
        r = left_right_swaps(p2.reshape(*shape, -1, 2), t2.reshape(*shape, -1, 2), v2.reshape(*shape, -1),
                             pred_valid=pv2.reshape(*shape, -1))
        every = r.evaluated.all(axis=1)
        # nan, not 0, where no pair was evaluated (max(n, 1) read as "never swapped"); the counts say why
        per_view = [_share(r.swapped[:, c].sum(), r.evaluated[:, c].sum()) for c in range(views)]
        return {"frac": r.value, "by_view": per_view, "evaluated": r.num_evaluated,
                "by_view_evaluated": [int(r.evaluated[:, c].sum()) for c in range(views)],
                "all_views_frac": _share((r.swapped.all(axis=1) & every).sum(), every.sum()),
                "all_views_evaluated": int(every.sum())}

    def summary(self) -> dict:
        if not self.p3:
            return {}
        ones = np.ones((len(self.p3), 25), bool)
        p3, t3, pv3, tracked = np.array(self.p3), np.array(self.t3), np.array(self.pv3), np.array(self.tracked)
        mp = mpjpe(p3, t3, ones, pred_valid=pv3)
        out = {"mpjpe_mm": mp.value, "mpjpe_evaluated": mp.num_evaluated, "mpjpe_pred_missing": mp.num_pred_missing,
               "found_3d_frac": float(pv3.mean()), "tracked_frac": float(tracked.mean())}
        if all(f is not None for f in self.frames):  # nan when no three frames chain
            follows = [False] + [b[0] == a[0] and b[1] == a[1] + 1 for a, b in zip(self.frames, self.frames[1:])]
            jit = acceleration_error(p3, t3, ones, pred_valid=pv3, consecutive=follows)
            out["jitter_mm"], out["jitter_evaluated"] = jit.value, jit.num_evaluated
        if all(v is not None for v in self.vis3):
            # how many cameras see each joint: the truth knows hidden joints, the MPJPE pools them all
            out["mpjpe_by_visibility"] = visibility_summary(mp, np.array(self.vis3), pv3, np.array(self.c3))
        if self.p2:
            p2, t2, v2, pv2 = (np.array(a) for a in (self.p2, self.t2, self.v2, self.pv2))
            pk = pck(p2, t2, v2, pred_valid=pv2)
            out.update({"pck@0.2": pk.value, "pck_evaluated": pk.num_evaluated,
                        "pck_pred_missing": pk.num_pred_missing})
            out["left_right_swaps"] = self._swaps(p2, t2, v2, pv2)
            # the 2D error in image pixels of the visible joints decoded: what triangulation amplifies
            out["error_2d_px"] = percentiles(np.linalg.norm(p2 - t2, axis=-1)[pk.evaluated & pv2], (50, 90))
        for name, sel in (("tracked", tracked), ("cold", ~tracked)):
            if sel.any():
                m = mpjpe(p3[sel], t3[sel], ones[sel], pred_valid=pv3[sel])
                out[f"mpjpe_mm_{name}"] = m.value
                out[f"found_3d_frac_{name}"] = float(pv3[sel].mean())
        return out


def _share(count, of) -> float:
    """``count / of``, nan when ``of`` is 0: a share of nothing is undefined, not 0."""
    return float(count / of) if of else float("nan")


def visibility_summary(result, visible: np.ndarray, found: np.ndarray,
                       confidence: np.ndarray | None = None) -> dict[str, dict]:
    """An MPJPE split by the cameras that see each joint (``metrics.mpjpe_by_visibility``), per class:
    ``mpjpe_mm`` over the joints found, ``joints`` found, ``share`` of all joints in the class and the
    share of them ``found`` (nan for an empty class), and with ``confidence`` the median confidence of
    the class's joints found (``confidence_median``): how far a user's confidence threshold tells
    hidden joints from seen ones.

    Args:
        result: ``metrics.mpjpe`` of ``(N, J)`` joints.
        visible: ``(N, C, J)`` per-camera visibility.
        found: ``(N, J)`` bool, the estimator produced the joint.
        confidence: optional ``(N, J)`` reported 3D confidence.
    """
    cls = visibility_class(visible)
    out = {}
    for k, (name, (total, n)) in enumerate(mpjpe_by_visibility(result, visible).items()):
        of = cls == k
        out[name] = {"mpjpe_mm": total / n if n else float("nan"), "joints": n, "share": float(of.mean()),
                     "found": float(found[of].mean()) if of.any() else float("nan")}
        if confidence is not None:
            sel = of & found
            out[name]["confidence_median"] = float(np.median(confidence[sel])) if sel.any() else float("nan")
    return out


def depth_per_disparity_px(rig: Rig, depth_m: float) -> float:
    """Metres of depth that one pixel of disparity error moves a point at ``depth_m`` for the rig's
    pair: ``z**2 / (f * b)``, the rectified-stereo approximation (``f`` the pair's mean focal length
    in pixels, ``b`` the baseline). Triangulation turns each view's 2D error into depth error at
    about this rate; it is how a 2D error in pixels becomes an MPJPE.

    Example:
        >>> from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, look_at
        >>> K = [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]]
        >>> cams = tuple(Camera(n, 640, 480, K, [], *look_at((x, 0, 0), (x, 0, 3))) for n, x in (("l", 0.0), ("r", 1.0)))
        >>> rig = Rig(cams, WorkingVolume(np.array([-1.0, -1, 2]), np.array([1.0, 1, 4])))
        >>> round(depth_per_disparity_px(rig, 3.0), 4)
        0.018
    """
    a, b = rig.pair
    focal = float(np.mean([a.K[0, 0], a.K[1, 1], b.K[0, 0], b.K[1, 1]]))
    return depth_m ** 2 / (focal * rig.baseline)


def percentiles(values, qs=(50, 99)) -> dict:
    """``{"median": ..., "p99": ...}`` of a list of numbers (nan when empty)."""
    a = np.asarray(values, np.float64)
    if a.size == 0:
        return {("median" if q == 50 else f"p{q}"): float("nan") for q in qs}
    return {("median" if q == 50 else f"p{q}"): float(np.percentile(a, q)) for q in qs}


def write_sim_example(out_dir: str | os.PathLike, *, seed: int = 3, motion: str = "wave", t: float = 0.4,
                      frames: int = 1, fps: float = 30.0, width: int = 640, height: int = 480) -> dict:
    """Write a simulated pair (or ``frames`` pairs) and its rig file: the docs' reproducible example.

    Files: ``rig.json``; ``<camera>.png`` per camera (``frames == 1``) or ``<camera>.mp4``
    (``mp4v``) otherwise; ``truth.json`` (true 3D joints per frame, metres). Returns the paths
    written (key per camera name, ``rig``, ``truth``).
    """
    from drivers.sim import RigPlacement, SceneConfig, SimScene  # tool only

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = RigPlacement(width=width, height=height).build(rig_id="sim-example")
    scene = SimScene(SceneConfig(seed=seed, motion=motion))
    save_rig(rig, out / "rig.json")
    paths = {"rig": str(out / "rig.json")}
    truth = []
    writers = {}
    for i in range(frames):
        ti = t + i / fps
        for cam in rig.pair:
            img, _ = scene.render(cam, ti, with_truth=False)
            if frames == 1:
                path = out / f"{cam.name}.png"
                cv2.imwrite(str(path), img)
                paths[cam.name] = str(path)
            else:
                if cam.name not in writers:
                    path = out / f"{cam.name}.mp4"
                    writers[cam.name] = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps,
                                                        (width, height))
                    paths[cam.name] = str(path)
                writers[cam.name].write(img)
        truth.append(np.round(scene.joints_3d(ti), 5).tolist())
    for w in writers.values():
        w.release()
    (out / "truth.json").write_text(json.dumps({"joints_3d": truth, "seed": seed, "motion": motion, "t": t,
                                                "fps": fps}))
    paths["truth"] = str(out / "truth.json")
    return paths
