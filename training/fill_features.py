"""What a learnt painter of the unseen surfaces reads at one novel view, cached per split.

``training.unseen_fill`` measures analytic fills of the surfaces no source camera sees;
``training.learnt_fill`` trains a network to do better from the same information. Both read what a
device could know (the source images, the geometry, the 3D joints), never the view's own image,
which is kept only as the training target. By default the geometry is the dataset's truth, so the
network's score bounds what a learnt appearance model adds once the geometry is right (the first
lever, which the model does not yet pull: docs/training.md, "Painting the unseen side from the
skeleton"). Given a GHNeRF checkpoint (``cache_split(model=...)``), everything a device would read
comes from that model instead (its depth at every view, its opacity above 0.5 as the subject, its
picture as the runtime shows it at ``novel_view.opaque_at``) but the 3D joints; the view's image and
mask stay the target. Given also the device's 3D joints (``cache_split(joints=...)``,
``training.device_joints``), the geometry is instead the body proxy built from them
(``training.body_proxy``, the template's mean girth) and the joints are those too, less those the runtime
leaves out (``training.device_joints.load_found``): then nothing but the
target comes from the truth.

Per novel view with a non-empty subject mask (numpy, one array per field, views stacked):

* ``blend`` / ``relit`` / ``shown`` / ``truth`` ``(H, W, 3)`` uint8 display colours: the two-camera
  blend at the geometry's depth (``training.blend_ceiling``); ``shown``, the model's picture as the
  runtime shows it (``novel_view.opaque_colour``; with the true geometry, ``relit``); ``relit``, the
  blend (with a model: ``shown``) with its unseen pixels repainted by ``unseen_fill.relit_fill``;
  and the view over black (the target, ``ghnerf-eval``'s);
* ``flags`` ``(H, W)`` uint8: bit 0 the geometry's subject mask less its pixels without a depth (a NaN
  depth is no surface: ``ghnerf_runtime.geometry.surface.surface_mask``, as on the device), bit 1 some
  source sees the pixel, bit 2 the true subject mask (the score's; the same as bit 0 with the true geometry);
* ``normals`` ``(H, W, 3)`` int8: camera-frame unit normals times 127 (zero off the subject, and where the
  depth is not finite: no surface there, its neighbours' normals taken from their own side, as on the device);
* ``depth`` ``(H, W)`` float16: camera z minus its median over the subject's finite depths, metres (zero off
  it), clipped to float16's largest finite value, a NaN zero as off the subject
  (``novel_painter.depth_about_median`` and ``float16_depth``, as on the device);
* ``joints`` ``(25, 3)`` float32: the 3D joints projected into the view (pixel u, v; valid 0/1);
* ``light`` ``(4,)`` float32: the fitted key light's direction in the camera frame and its ambient
  share (zeros when nothing was seen to fit it, or when the cache was made without the light fit:
  ``cache_split(relight=False)``, whose ``relit`` is then ``shown``; the runtime's painter reads
  neither, and the fit is a large share of a model cache's time);
* ``angle`` float32: the view's angle from the nearest source camera (``ghnerf-eval``'s bins);
* ``scene``, ``view`` int32: where it came from; ``geometry``: ``truth``, ``model`` or ``proxy``.

Beside the views, ``source`` (a JSON string) records where the cache came from: ``split``, ``dataset_sha256``
(of the dataset's ``dataset.json``), ``geometry``, ``model_sha256`` (the checkpoint's, '' with the true
geometry) and ``relight``. :func:`check_held_out` reads it (:func:`cache_source`) to refuse a validation cache
that is the training cache, of the training split or of the same split, or made from another dataset or
model: its held-out figures would be wrong without a word.

Cached as one uncompressed ``.npz`` per split (about 250 KB per view at 128x128), written whole (a temporary
file, then a rename: a stop mid-write leaves the previous cache); :func:`load_cache` names a cut or damaged
one (:class:`FillCacheError`).
"""
from __future__ import annotations

import io
import json
import multiprocessing as mp
import time
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ghnerf_runtime.geometry.surface import surface_mask
from ghnerf_runtime.novel_painter import depth_about_median, float16_depth
from training.blend_ceiling import blend_sources, project
from training.model_card import sha256, write_atomic
from training.unseen_fill import PART_BINS, Lighting, fit_lighting, relit_fill, seen_surface, surface_normals

FIELDS = ("blend", "relit", "shown", "truth", "flags", "normals", "depth", "joints", "light", "angle", "scene",
          "view", "geometry")
MASK_BIT, SEEN_BIT, TRUTH_BIT = 1, 2, 4
#: The cache's record of where it came from (module docstring); not a per-view field.
SOURCE_KEY = "source"
#: What a training and a validation cache must share: the held-out scores compare like with like.
SHARED_SOURCE = ("dataset_sha256", "geometry", "model_sha256")


class FillCacheError(ValueError):
    """A fill-feature cache that is missing, damaged, or the wrong one for its use; the message names the file."""


def _to_u8(rgb: np.ndarray) -> np.ndarray:
    return np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)


def render_views(renderer, scene: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``training.evaluate.TorchRenderer``'s colour ``(V, H, W, 3)``, depth and accumulated opacity
    ``(V, H, W)`` at every view of ``scene``."""
    from ghnerf_runtime.contract import ray_grid  # noqa: PLC0415

    V = len(scene["tgt_is_source"])
    H, W = renderer.height, renderer.width
    o = renderer.render(scene, np.arange(V), ray_grid(H, W, 1), heat=False)
    return o["rgb"].reshape(V, H, W, 3), o["depth"].reshape(V, H, W), o["acc"].reshape(V, H, W)


def modelled_scene(scene: Mapping[str, np.ndarray], depth: np.ndarray, acc: np.ndarray) -> dict:
    """``scene`` with a model's geometry in place of the truth: its depth at every view, and its opacity
    above 0.5 as the subject's masks (what a device knows)."""
    masks = acc > 0.5
    return {**scene, "tgt_depth": np.where(masks, depth, 0.0).astype(np.float32), "tgt_masks": masks}


def view_features(scene: Mapping[str, np.ndarray], view: int, lighting: Lighting | None,
                  angle: float, index: int = -1, truth: Mapping[str, np.ndarray] | None = None,
                  shown: np.ndarray | None = None, geometry: str | None = None,
                  relight: bool = True) -> dict[str, np.ndarray] | None:
    """One novel view's features (module docstring); ``None`` when the subject is not in it.

    ``scene`` carries the geometry (the truth, or :func:`modelled_scene`); ``truth`` the dataset item
    whose image and mask are the target (default ``scene``); ``shown`` the model's picture ``(H, W, 3)``
    (default: none, ``relit`` stands in); ``geometry`` the label (default: ``truth`` without ``shown``,
    else ``model``); ``relight`` false: no relit fill (``relit`` is the picture, ``light`` zeros)."""
    truth = scene if truth is None else truth
    subject = np.asarray(truth["tgt_masks"][view], bool)
    if not subject.any():
        return None
    depth = np.asarray(scene["tgt_depth"][view], np.float64)
    mask = surface_mask(depth, scene["tgt_masks"][view])  # a NaN depth is no surface: off, as on the device
    K_inv, c2w = scene["tgt_K_inv"][view], np.asarray(scene["tgt_c2w"][view], np.float64)
    blend, seen = blend_sources(scene, view, depth)
    picture = blend if shown is None else shown
    relit = (relit_fill(picture, scene, view, depth, mask & ~seen, mask=mask, lighting=lighting)
             if relight else picture)
    target = truth["tgt_images"][view].transpose(1, 2, 0) * subject[..., None]
    R = c2w[:, :3]  # camera to world: a world vector v is v @ R in the camera frame
    normals = surface_normals(depth, mask, K_inv, c2w) @ R
    z = depth_about_median(depth, mask)  # the median over the finite depths, as on the device
    u, v, jz = project(np.asarray(scene["joints_3d"], np.float64), scene["tgt_P"][view])
    valid = np.asarray(scene["joints_3d_valid"], bool) & (jz > 0)
    light = np.zeros(4, np.float32)
    if relight and lighting is not None:
        light[:3], light[3] = lighting.direction @ R, lighting.ambient
    return {
        "blend": _to_u8(blend), "relit": _to_u8(relit), "shown": _to_u8(relit if shown is None else shown),
        "truth": _to_u8(target),
        "flags": (mask * MASK_BIT + (mask & seen) * SEEN_BIT + subject * TRUTH_BIT).astype(np.uint8),
        "normals": np.round(np.where(mask[..., None], normals, 0.0) * 127.0).astype(np.int8),
        "depth": float16_depth(z),  # clipped as on the device: past 65504 m float16 is inf, and the painter NaN
        "joints": np.stack([np.where(valid, u, 0.0), np.where(valid, v, 0.0), valid], -1).astype(np.float32),
        "light": light, "angle": np.float32(angle), "scene": np.int32(index), "view": np.int32(view),
        "geometry": np.str_(geometry or ("truth" if shown is None else "model")),
    }


def scene_features(scene: Mapping[str, np.ndarray], index: int = -1, bins: int = PART_BINS,
                   renderer=None, joints: np.ndarray | None = None,
                   relight: bool = True, found: np.ndarray | None = None) -> list[dict[str, np.ndarray]]:
    """Features of every novel view of one dataset item (numpy arrays) that shows the subject.

    ``renderer``: a ``training.evaluate.TorchRenderer`` whose geometry and picture (at the runtime's
    ``novel_view.opaque_at``) replace the truth's; default the true geometry. ``joints``: with a
    renderer, the device's ``(25, 3)`` joints, whose body proxy is the geometry (module docstring);
    ``found``: which of them the runtime reports (``training.device_joints.load_found``: it leaves the
    others out of the proxy and the joint maps; default all).
    ``relight`` false skips the light fit and the relit fill (:func:`view_features`)."""
    from training.evaluate import source_angles_deg  # noqa: PLC0415 - torch-side module, loaded late

    if not np.asarray(scene["tgt_has_depth"], bool).all():
        return []  # no true depth (ZJU-MoCap): nothing to paint against
    V = len(scene["tgt_is_source"])
    angles = source_angles_deg(scene, np.arange(V))
    geometry, shown, label = scene, [None] * V, None
    if renderer is not None:
        from ghnerf_runtime.config import NovelViewConfig  # noqa: PLC0415
        from ghnerf_runtime.novel_view import opaque_colour  # noqa: PLC0415

        rgb, depth, acc = render_views(renderer, scene)
        if joints is None:
            geometry = modelled_scene(scene, depth, acc)
        else:
            from training.body_proxy import proxy_scene  # noqa: PLC0415

            valid = np.ones(len(joints), bool) if found is None else np.asarray(found, bool)
            geometry, _ = proxy_scene({**scene, "joints_3d": joints, "joints_3d_valid": valid}, joints, valid)
            label = "proxy"
        at = NovelViewConfig().opaque_at
        shown = [opaque_colour(rgb[t].reshape(-1, 3), acc[t].ravel(), renderer.background, at).reshape(rgb[t].shape)
                 for t in range(V)]
    lighting = fit_lighting(seen_surface(geometry, bins=bins)) if relight else None
    out = []
    for t in range(V):
        if scene["tgt_is_source"][t]:
            continue
        f = view_features(geometry, t, lighting, float(angles[t]), index, truth=scene, shown=shown[t], geometry=label,
                          relight=relight)
        if f is not None:
            out.append(f)
    return out


_WORKER: dict = {}


def _open(data: str, split: str, bins: int, model: str | None, joints: str | None = None,
          relight: bool = True) -> None:
    import torch  # noqa: PLC0415

    from training.data.torch_dataset import MultiViewDataset  # noqa: PLC0415

    renderer = None
    if model:
        from training.evaluate import TorchRenderer  # noqa: PLC0415
        from training.train import load_model  # noqa: PLC0415

        torch.set_num_threads(1)  # one scene per process
        renderer = TorchRenderer(load_model(Path(model))[0])
    if joints:
        from training.device_joints import load_found, load_joints  # noqa: PLC0415

        # the runtime leaves a joint whose expected error is past its gate out (joints3d.max_prior_error_m)
        joints, found = load_joints(joints), load_found(joints)
    else:
        found = None
    _WORKER.update(ds=MultiViewDataset(data, split=split), bins=bins, renderer=renderer, joints=joints,
                   found=found, relight=relight)


def _one(index: int) -> list[dict[str, np.ndarray]]:
    scene = {k: v.numpy() for k, v in _WORKER["ds"][index].items()}
    joints = _WORKER["joints"]
    if joints is not None and index >= len(joints):
        from training.device_joints import JointsCacheError  # noqa: PLC0415

        raise JointsCacheError(f"the joints cache holds {len(joints)} scenes; scene {index} asked for")
    return scene_features(scene, index, _WORKER["bins"], _WORKER["renderer"],
                          None if joints is None else joints[index], relight=_WORKER["relight"],
                          found=None if joints is None else _WORKER["found"][index])


def stack(views: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    if not views:
        raise ValueError("no novel view with the subject in it: nothing to cache")
    return {k: np.stack([f[k] for f in views]) for k in FIELDS}


def cache_split(data: str | Path, split: str, out: str | Path, limit: int = 0, workers: int = 2,
                bins: int = PART_BINS, model: str | Path | None = None, joints: str | Path | None = None,
                relight: bool = True, log=print) -> Path:
    """Compute the features of a split's first ``limit`` scenes (0: all) and write them to ``out`` (.npz).

    ``model``: a GHNeRF checkpoint whose geometry and picture replace the truth's; ``joints``: with it,
    a ``training.device_joints`` cache of the same split whose body proxy is the geometry (module
    docstring); ``relight`` false: no light fit nor relit fill (for the runtime's painter, which reads
    neither)."""
    from training.data.torch_dataset import MultiViewDataset  # noqa: PLC0415

    if joints is not None and model is None:
        raise ValueError("a joints cache takes a model too (its picture is the one repainted)")
    n = len(MultiViewDataset(data, split=split))
    n = min(limit, n) if limit else n
    if joints is not None:  # here, not in the workers' initializer (a pool respawns a worker that fails there,
        # for ever: a cache of the right split without its joints or expected errors hung the command)
        from training.device_joints import check_source, load_found, load_joints  # noqa: PLC0415

        check_source(joints, data, split)
        load_joints(joints, n)  # covering every scene asked for: a short cache is named now, not in a worker
        load_found(joints, n)
    if model is not None and workers > 1:  # the same: a checkpoint the initializer failed to load hung the pool
        from training.train import load_model  # noqa: PLC0415

        load_model(Path(model))  # a ConfigError naming the file
    t0, views = time.monotonic(), []
    if workers > 1:
        init = (str(data), split, bins, model and str(model), joints and str(joints), relight)
        with mp.get_context("spawn").Pool(workers, initializer=_open, initargs=init) as pool:
            for i, fs in enumerate(pool.imap(_one, range(n), chunksize=4)):
                views.extend(fs)
                if (i + 1) % 256 == 0:
                    log(f"  {split}: {i + 1}/{n} scenes, {time.monotonic() - t0:.0f} s")
    else:
        _open(str(data), split, bins, model and str(model), joints and str(joints), relight)  # in this process
        for i in range(n):
            views.extend(_one(i))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # whole or not at all: savez straight into ``out`` left a cut zip after a stop mid-write, which a rerun's
    # training then failed to open (and the previous cache was gone); written to that very name, .npz or not
    source = {"split": split, "dataset_sha256": sha256(Path(data) / "dataset.json"),
              "geometry": "truth" if model is None else "model" if joints is None else "proxy",
              "model_sha256": "" if model is None else sha256(model), "relight": bool(relight)}
    buf = io.BytesIO()
    np.savez(buf, **stack(views), **{SOURCE_KEY: np.str_(json.dumps(source))})
    write_atomic(out, buf.getvalue())
    log(f"{out}: {len(views)} views of {n} {split} scenes in {time.monotonic() - t0:.0f} s")
    return out


def relit_in(arrays: Mapping[str, np.ndarray]) -> bool:
    """Whether a cache holds a relit fill (made with the light fit): some view has a fitted light."""
    return bool(np.asarray(arrays["light"]).any())


def load_cache(path: str | Path) -> dict[str, np.ndarray]:
    """A cache written by :func:`cache_split`, checked for every field: the per-view arrays (not its
    ``source`` record: :func:`cache_source`)."""
    path = Path(path)
    try:
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files if k != SOURCE_KEY}
    # a cut or damaged zip is BadZipFile (an empty file EOFError), neither an OSError nor a ValueError
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise FillCacheError(f"{path}: not a fill-feature cache, or a damaged one: make it again ({e})") from e
    missing = [k for k in FIELDS if k not in arrays]
    if missing:
        raise FillCacheError(f"{path}: fill-feature cache lacks {', '.join(missing)}")
    n = {k: len(arrays[k]) for k in FIELDS}
    if len(set(n.values())) != 1:
        raise FillCacheError(f"{path}: fill-feature fields disagree on the number of views: {n}")
    if not n[FIELDS[0]]:  # train, score and export each failed on it in numpy or onnxruntime, a traceback
        raise FillCacheError(f"{path}: fill-feature cache holds no views: nothing to train, score or calibrate on")
    return arrays


def cache_source(path: str | Path) -> dict | None:
    """Where the cache at ``path`` came from (module docstring), or None for a cache made before the record."""
    path = Path(path)
    try:
        with np.load(path) as z:
            if SOURCE_KEY not in z.files:
                return None
            return json.loads(str(z[SOURCE_KEY]))
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:  # json's errors are ValueErrors too
        raise FillCacheError(f"{path}: not a fill-feature cache, or a damaged one: make it again ({e})") from e


def check_held_out(train: str | Path, val: str | Path) -> None:
    """Refuse a validation cache ``val`` that does not hold out ``train``'s views: the same file, the same split,
    the training split, or made from another dataset, geometry or model (the scores would compare another
    thing). Caches made before the ``source`` record are checked for being the same file only."""
    train, val = Path(train), Path(val)
    if train.resolve() == val.resolve():
        raise FillCacheError(f"--train-cache and --val-cache are the same file ({train}): the held-out figures "
                             "would be those of the training views")
    t, v = cache_source(train), cache_source(val)
    if t is None or v is None:
        return
    if t["split"] == v["split"]:
        raise FillCacheError(f"--train-cache {train} and --val-cache {val} both hold split {t['split']!r}: "
                             "validate on a held-out split (cache --split val)")
    if v["split"] == "train":
        raise FillCacheError(f"--val-cache {val} holds the training split 'train' (and --train-cache {train} "
                             f"split {t['split']!r}): the two caches are swapped")
    for key in SHARED_SOURCE:
        if t.get(key) != v.get(key):
            raise FillCacheError(f"--train-cache {train} and --val-cache {val} differ in {key} ({t.get(key)!r} vs "
                                 f"{v.get(key)!r}): make both from the same dataset, geometry and model")


__all__ = ["FIELDS", "MASK_BIT", "SEEN_BIT", "TRUTH_BIT", "SOURCE_KEY", "FillCacheError", "render_views",
           "modelled_scene", "view_features", "scene_features", "stack", "cache_split", "load_cache", "cache_source",
           "check_held_out", "relit_in"]
