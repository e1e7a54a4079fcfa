"""The pre-rendered motion loop of ``sim://``: every frame of both cameras, rendered once.

Rendering a frame costs far more than a 30 fps frame period on a small CPU, but
the synthetic motion repeats, so a simulated frame is a function of (camera,
frame index modulo the loop length). :class:`FrameLoop` renders the whole loop
with a small thread pool (the renderer is numpy, which releases the GIL) into
preallocated arrays, and can keep the result in an on-disk cache directory of
``.npy`` files (memory-mapped when loaded, so a cached loop opens in one read of
its files, the checksum check below, and the OS shares its pages between processes).

The cache directory's name is a hash of everything that changes the pixels;
entries are written to a temporary directory, fsynced (files, then the folder)
and renamed into place (the cache root fsynced after), so readers never see half
an entry, and a power cut cannot leave a named entry whose files hold zeros.
``meta.json`` records each file's size and CRC-32, checked when an entry is
loaded (one read of the loop, ~3 GB/s): an entry that does not match (written
by a disk that lied, or damaged since) is rendered again rather than served as
black frames. Cache problems are logged and never fatal.

A :meth:`FrameLoop.close` (or the owner's ``stop`` event) during :meth:`FrameLoop.fill` stops it at its next
step, whatever it is doing: the next frame rendered, the next chunk of the cache's checksum check (a loaded entry
stays, intact), the next chunk written (the half-written temporary entry is removed, never renamed into place):
``fill`` raises :class:`FillCancelled`.
"""
from __future__ import annotations

import concurrent.futures
import json
import logging
import os
import shutil
import threading
import time
import uuid
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.errors import RigInitializationError
from drivers.frames import CameraTruth

log = logging.getLogger(__name__)

_CAMERA_FIELDS = ("image", "mask", "depth", "part_labels", "joints_2d", "visible", "joints_3d", "scene_time_s")
# bump when the files below change meaning; 2: fsynced entries with checksums (layout 1 entries were not fsynced,
# so one may hold zeros after a power cut: they are rendered again, once)
CACHE_LAYOUT = 2
_CHUNK = 8 << 20  # bytes read at a time to check a file's checksum


@dataclass(frozen=True, eq=False)
class LoopFrame:
    """One rendered frame: image, ground truth, the scene instant it shows and the 3D joints then."""

    image: np.ndarray
    truth: CameraTruth
    scene_time_s: float
    joints_3d: np.ndarray


@dataclass(frozen=True)
class FillReport:
    """How a loop became ready."""

    source: str  # "rendered" or "disk"
    frames: int
    wall_s: float
    render_s_per_frame: float  # mean time of one render call (0 when loaded from disk)


RenderFn = Callable[[int, int], LoopFrame]  # (camera position 0/1, loop frame) -> frame


class FillCancelled(RigInitializationError):
    """:meth:`FrameLoop.fill` stopped by a close (its own or its owner's ``stop``); the message says at which
    step (rendering, the cache load, the cache write)."""


def default_cache_root() -> Path:
    """``$XDG_CACHE_HOME/ghnerf-sim``, else ``~/.cache/ghnerf-sim``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ghnerf-sim"


class FrameLoop:
    """All ``cameras x length`` frames of the loop, in arrays.

    Args:
        render: renders one frame; called from worker threads.
        length: frames per camera in the loop.
        cameras: number of cameras (2).
        workers: render threads.
        cache_dir: this loop's cache entry (``root/<key>``), or ``None`` for no disk cache.
        stop: the owner's event that, once set, stops a fill as :meth:`close` does (only read here): a source's
            close, set before the loop exists or while it fills.
    """

    def __init__(self, render: RenderFn, length: int, *, cameras: int = 2, workers: int = 2,
                 cache_dir: Path | None = None, stop: threading.Event | None = None) -> None:
        self._render = render
        self.length = length
        self.cameras = cameras
        self.workers = max(1, workers)
        self.cache_dir = cache_dir
        self._arrays: dict[str, np.ndarray] = {}
        self._cancel = threading.Event()
        self._stop = stop
        self._render_time = 0.0
        self._time_lock = threading.Lock()
        self.ready = False

    # ------------------------------------------------------------------ fill
    def fill(self, progress: Callable[[int, int, float], None] | None = None) -> FillReport:
        """Make every frame available: load the disk cache, else render (and store) the loop.

        Args:
            progress: called about every 2 s while rendering with (done, total, elapsed seconds).

        Raises:
            RigInitializationError: rendering failed (the renderer's error is the cause).
            FillCancelled: :meth:`close` was called (or ``stop`` set) meanwhile.
        """
        t0 = time.perf_counter()
        if self.cache_dir is not None and self._load():
            self.ready = True
            return FillReport("disk", self.cameras * self.length, time.perf_counter() - t0, 0.0)
        self._render_all(progress)
        self.ready = True
        wall = time.perf_counter() - t0
        if self.cache_dir is not None:
            self._store()
        total = self.cameras * self.length
        return FillReport("rendered", total, wall, self._render_time / total)

    def _stop_if_cancelled(self, step: str) -> None:
        if self._cancel.is_set() or (self._stop is not None and self._stop.is_set()):
            raise FillCancelled(f"sim loop's {step} cancelled (source closed)")

    def _timed_render(self, camera: int, j: int) -> LoopFrame:
        self._stop_if_cancelled("pre-render")
        t = time.perf_counter()
        frame = self._render(camera, j)
        with self._time_lock:
            self._render_time += time.perf_counter() - t
        return frame

    def _render_all(self, progress) -> None:
        first = self._timed_render(0, 0)  # its shapes and dtypes size the arrays
        self._allocate(first)
        self._put(0, 0, first)
        jobs = [(c, j) for j in range(self.length) for c in range(self.cameras)][1:]
        t0 = time.perf_counter()
        with concurrent.futures.ThreadPoolExecutor(self.workers, thread_name_prefix="sim-render") as pool:
            futures = {pool.submit(self._timed_render, c, j): (c, j) for c, j in jobs}
            pending = set(futures)
            try:
                while pending:
                    done, pending = concurrent.futures.wait(pending, timeout=2.0)
                    for future in done:
                        c, j = futures[future]
                        self._put(c, j, future.result())
                    if pending and progress is not None:
                        progress(len(futures) - len(pending) + 1, len(futures) + 1, time.perf_counter() - t0)
            except BaseException as e:
                self._cancel.set()  # workers stop taking frames; queued ones are cancelled
                for future in pending:
                    future.cancel()
                if isinstance(e, RigInitializationError) or not isinstance(e, Exception):
                    raise  # ours already, or KeyboardInterrupt/SystemExit: not a render failure
                raise RigInitializationError(f"sim pre-render failed: {e}") from e

    def _allocate(self, first: LoopFrame) -> None:
        for name, value in self._fields(first).items():
            value = np.asarray(value)
            self._arrays[name] = np.empty((self.cameras, self.length) + value.shape, dtype=value.dtype)

    @staticmethod
    def _fields(frame: LoopFrame) -> dict[str, np.ndarray]:
        t = frame.truth
        return {
            "image": frame.image, "mask": t.mask, "depth": t.depth, "part_labels": t.part_labels,
            "joints_2d": t.joints_2d, "visible": t.visible, "joints_3d": frame.joints_3d,
            "scene_time_s": np.float64(frame.scene_time_s),
        }

    def _put(self, camera: int, j: int, frame: LoopFrame) -> None:
        for name, value in self._fields(frame).items():
            self._arrays[name][camera, j] = value

    # ------------------------------------------------------------------ access
    def frame(self, camera: int, j: int) -> LoopFrame:
        """Frame ``j`` of ``camera``. The image is a fresh copy (consumers may draw on it);
        truth arrays are read-only views shared by every pass of the loop."""
        a = self._arrays
        truth = CameraTruth(
            joints_2d=_readonly(a["joints_2d"][camera, j]), visible=_readonly(a["visible"][camera, j]),
            mask=_readonly(a["mask"][camera, j]), depth=_readonly(a["depth"][camera, j]),
            part_labels=_readonly(a["part_labels"][camera, j]),
        )
        return LoopFrame(
            image=np.array(a["image"][camera, j]),
            truth=truth,
            scene_time_s=float(a["scene_time_s"][camera, j]),
            joints_3d=_readonly(a["joints_3d"][camera, j]),
        )

    def nbytes(self) -> int:
        return sum(a.nbytes for a in self._arrays.values())

    def close(self) -> None:
        self._cancel.set()

    # ------------------------------------------------------------------ disk
    def _load(self) -> bool:
        assert self.cache_dir is not None
        meta_path = self.cache_dir / "meta.json"
        if not meta_path.is_file():
            return False
        try:
            meta = json.loads(meta_path.read_text())
            if meta.get("layout") != CACHE_LAYOUT or meta.get("shape") != [self.cameras, self.length]:
                raise ValueError(f"layout/shape mismatch: {meta}")
            _check_files(self.cache_dir, meta, lambda: self._stop_if_cancelled(f"load from cache {self.cache_dir}"))
            arrays = {name: np.load(self.cache_dir / f"{name}.npy", mmap_mode="r") for name in _CAMERA_FIELDS}
            for name, array in arrays.items():
                if array.shape[:2] != (self.cameras, self.length):
                    raise ValueError(f"{name}.npy has shape {array.shape}")
        except (OSError, ValueError) as e:
            log.warning("sim cache entry %s unusable (%s); rendering again", self.cache_dir, e)
            self._discard_entry()
            return False
        self._arrays = arrays
        log.info("sim loop loaded from cache %s", self.cache_dir)
        return True

    def _discard_entry(self) -> None:
        """Move an unusable entry aside and delete it, so that the new render can take its place
        (else every later open would render again: a rename cannot replace a non-empty folder)."""
        assert self.cache_dir is not None
        stale = self.cache_dir.with_name(f".{self.cache_dir.name}.{uuid.uuid4().hex[:8]}.stale")
        try:
            os.replace(self.cache_dir, stale)  # atomic: a concurrent reader's mmaps stay valid
        except OSError as e:
            log.warning("sim cache entry %s could not be moved aside: %s", self.cache_dir, e)
            return
        shutil.rmtree(stale, ignore_errors=True)

    def _store(self) -> None:
        assert self.cache_dir is not None
        tmp = self.cache_dir.with_name(f".{self.cache_dir.name}.{uuid.uuid4().hex[:8]}.tmp")
        try:
            tmp.mkdir(parents=True)
            files = {}
            for name, array in self._arrays.items():
                with open(tmp / f"{name}.npy", "wb") as f:
                    summed = _Crc32Writer(f, lambda: self._stop_if_cancelled(f"write to cache {self.cache_dir}"))
                    np.save(summed, array)
                    f.flush()
                    os.fsync(f.fileno())  # on disk before the rename names the entry (else: zeros after a power cut)
                files[f"{name}.npy"] = {"bytes": summed.size, "crc32": summed.crc}
            meta = {"layout": CACHE_LAYOUT, "shape": [self.cameras, self.length], "files": files}
            with open(tmp / "meta.json", "w", encoding="utf-8") as f:
                f.write(json.dumps(meta))
                f.flush()
                os.fsync(f.fileno())
            _fsync_dir(tmp)
            os.replace(tmp, self.cache_dir)
            _fsync_dir(self.cache_dir.parent)  # the rename itself
            log.info("sim loop stored in cache %s (%.0f MB)", self.cache_dir, self.nbytes() / 1e6)
        except OSError as e:
            # A concurrent writer may have won the rename; either way the cache is optional.
            log.warning("sim cache entry %s not stored: %s", self.cache_dir, e)
            shutil.rmtree(tmp, ignore_errors=True)
        except BaseException:  # cancelled (FillCancelled), a Ctrl-C: the half-written entry is never named
            shutil.rmtree(tmp, ignore_errors=True)
            raise


class _Crc32Writer:
    """A binary file that np.save writes through, summing what it writes (no second read of the loop).
    ``before_write`` runs before each chunk (np.save writes one of at most 16 MB at a time): it raises to stop."""

    def __init__(self, file, before_write: Callable[[], None]) -> None:
        self._file = file
        self._before_write = before_write
        self.crc = 0
        self.size = 0

    def write(self, data) -> int:
        self._before_write()
        view = memoryview(data).cast("B")
        self.crc = zlib.crc32(view, self.crc)
        self.size += view.nbytes
        return self._file.write(view)


def _check_files(entry: Path, meta: dict, before_chunk: Callable[[], None]) -> None:
    """Raise ValueError naming the first file of ``entry`` whose size or CRC-32 is not what ``meta`` recorded.
    ``before_chunk`` runs before each chunk read: it raises to stop (a close)."""
    files = meta.get("files")
    if not isinstance(files, dict):
        raise ValueError("meta.json lists no file checksums")
    for name in _CAMERA_FIELDS:
        expected = files.get(f"{name}.npy")
        if not isinstance(expected, dict):
            raise ValueError(f"meta.json has no checksum of {name}.npy")
        crc, size = 0, 0
        with open(entry / f"{name}.npy", "rb") as f:
            while True:
                before_chunk()
                chunk = f.read(_CHUNK)
                if not chunk:
                    break
                crc = zlib.crc32(chunk, crc)
                size += len(chunk)
        if (size, crc) != (expected.get("bytes"), expected.get("crc32")):
            raise ValueError(f"{name}.npy does not match its checksum ({size} bytes, CRC-32 {crc:08x}; recorded "
                             f"{expected.get('bytes')} bytes, {expected.get('crc32')}): damaged or never fully written")


def _fsync_dir(path: Path) -> None:
    """Make a folder's entries durable; not possible on every platform (then only logged)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError as e:
        log.debug("sim cache: cannot open folder %s to fsync it: %s", path, e)
        return
    try:
        os.fsync(fd)
    except OSError as e:
        log.debug("sim cache: fsync of folder %s: %s", path, e)
    finally:
        os.close(fd)


def _readonly(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view
