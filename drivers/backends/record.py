"""``record+<url>``: pass frames through from any backend while writing them as a recording.

pyserial's ``spy://`` idea: the recorder wraps the inner source, hands every frame
on unchanged and copies it to a directory that ``replay://`` plays back
(layout: docs/recording-format.md).

URL syntax: the recorder's own options sit in the same query as the inner
backend's and are removed before the inner URL is parsed::

    record+sim://?fps=30&seed=3&out=/data/take1
    record+depthai://?fps=30&out=/data/take2&image_format=jpg&jpeg_quality=90

Recorder options (inner backends never see them, so none may reuse these names):

* ``out`` (required, or the ``out=`` keyword argument): the directory; it must
  not exist or be empty.
* ``image_format``: ``png`` (default, lossless) or ``jpg``.
* ``jpeg_quality``: 1..100 (default 95).
* ``write_queue``: frames buffered for the writers (default 64).
* ``writers``: writer threads (default 2; encoding releases the GIL).
* ``lossless``: ``1`` makes the reader wait for a free queue slot instead of
  dropping the frame: for offline recording (e.g. ``record+sim`` on a
  ``ManualClock``, which reads faster than real time), never for a live rig.
  A ``close()`` from another thread ends that wait: the read raises
  :class:`~drivers.errors.RigOperationError` ("closed while a read waited"), as
  every backend's read does that a close lands in, and the frame is not recorded.
  A close past ``close_timeout_s`` loses what was still queued, ``lossless`` or not.
* ``close_timeout_s``: seconds ``close()`` waits for the writers to finish the queue, fsync the take and rewrite
  its manifest (default 10; the manifest gets at least :data:`MANIFEST_WAIT_FLOOR_S`; a slow disk behind a long
  ``write_queue`` may need more). Past it (a dead disk: a USB stick pulled, an NFS mount gone) close stops waiting:
  the take is left ``complete: false`` with ``close_timed_out_s`` in its counters,
  :meth:`RecordingRigSource.unreported_failure` says "the take's last frames were not written: the disk stopped
  answering", and the writer threads still stuck in a write are left behind (daemon threads), named by
  :meth:`~drivers.base.RigSource.lingering`.

A ``close()`` from another thread while ``open()`` runs goes on to the inner source at once, cancelling its open
(``sim://``'s pre-render stops at its next frame, ``opencv://``'s wait for its first frames ends): ``open()`` raises
:class:`~drivers.errors.RigInitializationError` and no take is started; one that lands after the inner source opened
closes it, and the take if one was started.
After the close, :meth:`~drivers.base.RigSource.lingering` is the inner source's (an ``opencv://`` camera thread still
in a grab, or a camera or ``depthai://`` device its cancelled open has not released yet; it was always empty, hiding
a device still held), then the recorder's threads a close past ``close_timeout_s`` left in a write.

Recording never stalls the reader (unless ``lossless=1``): frames go into a
bounded queue drained by writer threads; when it is full the frame is not
recorded and counted in ``stats.writes_dropped``. Every frame the inner camera delivered is recorded,
paired or not, so a replay meets the same pairing situations. A write failure
(disk full...) is raised once from the next ``read()`` as
:class:`~drivers.errors.RecordingError` (a :class:`RigOperationError`); after that frames pass through
unrecorded.

Durability: files are not fsynced per frame on the read path (too slow for small
disks): the writer threads fsync them in batches of :data:`SYNC_BATCH` files as
they go (so the backlog stays bounded and close stays quick); at close the
writers fsync what is outstanding, then the folders and the journal are fsynced,
and only then is the manifest rewritten with ``complete: true`` (itself fsynced),
so the mark never reaches the disk before the data it vouches for. A take cut
short before that stays ``complete: false``; replay drops the rows whose files are missing, empty or
cut short.
"""
from __future__ import annotations

import datetime
import logging
import os
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from urllib.parse import quote, urlencode

from drivers.base import RigSource
from drivers.backends.recording_format import (
    CLOSE_TIMED_OUT,
    IMAGE_FORMATS,
    FRAMES,
    FrameRow,
    Manifest,
    camera_dir_name,
    encode_image,
    frame_has_truth,
    write_manifest,
    write_truth,
)
from drivers.errors import RecordingError, RigConfigError, RigInitializationError, RigOperationError
from drivers.frames import Frame
from drivers.pairing import PairingStats
from drivers.url import RigUrl, redact_url
from ghnerf_runtime.path_check import shown
from ghnerf_runtime.rig_file import principal_point_problem

log = logging.getLogger(__name__)

#: Options the recorder consumes from the URL.
RECORD_OPTIONS = ("out", "image_format", "jpeg_quality", "write_queue", "writers", "lossless", "close_timeout_s")

#: Written files a writer thread lets pile up before it fsyncs them (bounds the backlog close must fsync).
SYNC_BATCH = 64

#: Seconds a lossless submit waits for a queue slot before it looks again whether the writer was closed: the
#: writers stop at close, so a reader left waiting on a full queue then would wait for good.
SUBMIT_WAIT_SLICE_S = 0.05

#: Seconds the manifest's last rewrite is given at least, where the writers took (nearly) all of ``close_timeout_s``:
#: a slow disk that did write the take still gets its ``complete: true``. Keeps a close with the default 10 s within
#: the daemon unit's ``TimeoutStopSec=20``.
MANIFEST_WAIT_FLOOR_S = 1.0


@dataclass(frozen=True)
class RecordOptions:
    """How and where to record (see the module docstring for the URL options)."""

    out: Path
    image_format: str = "png"
    jpeg_quality: int = 95
    write_queue: int = 64
    writers: int = 2
    lossless: bool = False
    close_timeout_s: float = 10.0

    @classmethod
    def take_from(cls, url: RigUrl, out: str | Path | None = None) -> "RecordOptions":
        """Consume the recorder's options from ``url`` (the ``out`` keyword wins over ``out=``)."""
        url_out = url.take_str("out")
        target = out if out is not None else url_out
        if not target:
            raise RigConfigError(f"rig URL 'record+{url.url}': option out=DIR (the recording directory) is required")
        return cls(
            out=Path(target),
            image_format=url.take_str("image_format", "png", choices=tuple(IMAGE_FORMATS)) or "png",
            jpeg_quality=url.take_int("jpeg_quality", 95, lo=1, hi=100),
            write_queue=url.take_int("write_queue", 64, lo=1, hi=10_000),
            writers=url.take_int("writers", 2, lo=1, hi=16),
            lossless=url.take_bool("lossless", False),
            close_timeout_s=url.take_float("close_timeout_s", 10.0, lo=0.001, hi=86_400.0),
        )


@dataclass
class RecordingStats(PairingStats):
    """Pairing counters plus what the recorder wrote and what it had to skip."""

    frames_written: int = 0
    writes_dropped: int = 0


def inner_url_text(url: RigUrl) -> str:
    """The URL text for what is left of ``url`` once the recorder took its options."""
    text = f"{url.scheme}://{quote(url.target, safe='/:,@')}"
    # quote, not urlencode's default quote_plus: a rig URL reads '+' as a plus (drivers.url), so a space written
    # '+' came back a plus (record+opencv://?first=/v/my%20take.mp4 opened /v/my+take.mp4)
    return f"{text}?{urlencode(url.options, quote_via=quote)}" if url.options else text


class RecordingWriter:
    """Writes frames into a recording directory from worker threads fed by a bounded queue."""

    def __init__(self, directory: Path, manifest: Manifest, options: RecordOptions) -> None:
        self.directory = directory
        self.manifest = manifest
        self.options = options
        self.frames_written = 0
        self._submit_dropped = 0  # by the reader thread: a full queue, a failed writer
        self._writer_dropped = 0  # by the writer threads (under _journal_lock): the failed frame, the rest drained
        self.error: BaseException | None = None
        self._queue: queue.Queue[tuple[Frame, FrameRow] | None] = queue.Queue(options.write_queue)
        self._per_camera: dict[str, int] = {}
        self._journal_lock = threading.Lock()
        self._journal = None
        self._threads: list[threading.Thread] = []
        # Set first thing in close: a submit after it (a read in another thread) is refused, never left waiting
        # on a queue the stopped writers no longer drain.
        self._stopping = threading.Event()
        # Held by a submit from its look at _stopping to its put, and taken by close once _stopping is set: a frame
        # is queued ahead of the writers' stop marks (written, or counted dropped) or refused, never left behind them.
        self._submit_lock = threading.Lock()
        # Payload files written, not fsynced yet (relative paths, under the journal lock): a writer that
        # brings it to SYNC_BATCH takes the batch and fsyncs it, off the reader's path.
        self._unsynced: list[str] = []
        self._folders: set[Path] = set()  # folders of the files fsynced, for close (a few: one per camera and kind)
        self._submitted = 0  # frames queued (by the reader thread): what a close past its deadline left unwritten
        # Set by a close that stopped waiting (close_timeout_s): why the take's end is missing. Kept apart from
        # `error`, which a stuck writer may still set when its write finally fails.
        self.close_timed_out: RecordingError | None = None
        self._close_threads: list[threading.Thread] = []  # the close's own helpers, for lingering()

    def start(self) -> None:
        # replay reads the manifest's rig with rig_from_dict: refuse a rig it would refuse, before any file is made
        for cam in self.manifest.rig.cameras:
            problem = principal_point_problem(cam.K, cam.width, cam.height)
            if problem:
                raise RigInitializationError(
                    f"cannot record to {shown(str(self.directory))}: the take could not be replayed: "
                    f"camera {cam.name!r}: {problem}"
                )
        created: list[Path] = []  # what this start made, in order: undone if it fails
        try:
            missing = [d for d in (self.directory, *self.directory.parents) if not d.exists()]
            self.directory.mkdir(parents=True, exist_ok=True)
            created.extend(reversed(missing))
            if any(self.directory.iterdir()):
                raise RigInitializationError(
                    f"recording directory {shown(str(self.directory))} is not empty; choose a new out= directory"
                )
            # Claim the folder first, exclusively: of two recorders started on it at once (both found it
            # empty) only one goes on; the other, with other camera names, would mix its frames into the take.
            try:
                self._journal = open(self.directory / FRAMES, "x", encoding="utf-8")
            except FileExistsError:
                raise RigInitializationError(
                    f"recording directory {shown(str(self.directory))} is being written by another recorder "
                    f"({FRAMES} appeared after it was found empty); choose a new out= directory"
                ) from None
            created.append(self.directory / FRAMES)
            for cam in self.manifest.rig.names:
                name = camera_dir_name(self.manifest.rig, cam)
                for kind in ("images", "truth"):
                    for folder in (self.directory / kind, self.directory / kind / name):
                        if not folder.exists():
                            folder.mkdir()
                            created.append(folder)
            write_manifest(self.directory, self.manifest)
        except (OSError, RigOperationError) as e:  # RigOperationError: the manifest (a full disk)
            self._undo_start(created)
            raise RigInitializationError(f"cannot start recording in {shown(str(self.directory))}: {e}") from e
        except BaseException:
            self._undo_start(created)
            raise
        for i in range(self.options.writers):
            thread = threading.Thread(target=self._run, name=f"rig-recorder-{i}", daemon=True)
            thread.start()
            self._threads.append(thread)
        log.info("recording to %s (%s images)", self.directory, self.options.image_format)

    def _undo_start(self, created: list[Path]) -> None:
        """A start that failed (a full disk at the manifest) leaves the folder as it found it: a journal and
        camera folders without a manifest are no take, yet made ``out=`` "not empty", so a retry after freeing
        space was refused. Only what this start made goes, newest first; anything else stays."""
        if self._journal is not None:
            self._journal.close()
            self._journal = None
        for path in reversed(created):
            try:
                path.rmdir() if path.is_dir() else path.unlink()
            except OSError as e:  # not empty (another program wrote there meanwhile), or gone: leave it
                log.debug("recording: not removing %s after a failed start: %s", path, e)

    @property
    def writes_dropped(self) -> int:
        """Frames not written, every one counted: ``frames_written + writes_dropped`` is every frame submitted."""
        return self._submit_dropped + self._writer_dropped

    def submit(self, frame: Frame) -> None:
        """Queue ``frame`` for writing; a full queue or a failed writer drops it, counted (``lossless``: waits).

        Raises:
            RigOperationError: the writer was closed (from another thread) before this queued the frame (as it
                copied it; lossless: as it waited for a slot): the frame is not recorded, nor counted (no read hands
                it out).
        """
        if self._stopping.is_set():
            raise self._closed_error()
        if self.error is not None:
            self._submit_dropped += 1
            return
        n = self._per_camera.get(frame.camera, 0)
        cam_dir = camera_dir_name(self.manifest.rig, frame.camera)
        ext = IMAGE_FORMATS[self.options.image_format]
        row = FrameRow(
            camera=frame.camera,
            index=frame.index,
            timestamp_ns=frame.timestamp_ns,
            image=f"images/{cam_dir}/{n:08d}{ext}",
            truth=f"truth/{cam_dir}/{n:08d}.npz" if frame_has_truth(frame) else None,
            scene_time_s=frame.scene_time_s,
        )
        # The writers encode later, and a reader may draw on the image it was handed meanwhile:
        # record what the camera captured, not the annotated picture.
        frame = replace(frame, image=frame.image.copy())
        if not self._put((frame, row)):
            self._submit_dropped += 1
            return
        self._submitted += 1
        self._per_camera[frame.camera] = n + 1

    def _put(self, item: tuple[Frame, FrameRow]) -> bool:
        """Queue ``item``; False: the queue is full (not ``lossless``). Raises once close began (the frame was
        copied meanwhile, or a lossless wait looked again after :data:`SUBMIT_WAIT_SLICE_S`): the writers stop, and
        a frame queued then would sit behind their stop marks, never written nor counted."""
        while True:
            with self._submit_lock:
                if self._stopping.is_set():
                    raise self._closed_error()
                try:
                    self._queue.put(item, block=self.options.lossless, timeout=SUBMIT_WAIT_SLICE_S)
                    return True
                except queue.Full:
                    if not self.options.lossless:
                        return False

    def _closed_error(self) -> RigOperationError:
        return RigOperationError(
            f"recording to {shown(str(self.directory))} closed while a read waited to queue its frame; "
            "the frame is not recorded"
        )

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self.error is not None:  # drain without writing: the recording already failed
                with self._journal_lock:
                    self._writer_dropped += 1
                continue
            frame, row = item
            written = False  # its row in the journal: counted there, not dropped, if a later fsync fails
            journaled = False  # its row handed to the journal: a flush retried at close may still write it: files kept
            try:
                data = encode_image(frame.image, self.options.image_format, self.options.jpeg_quality)
                (self.directory / row.image).write_bytes(data)
                if row.truth is not None:
                    write_truth(self.directory / row.truth, frame.truth, frame.joints_3d)
                with self._journal_lock:  # the row goes in only once its files are complete
                    assert self._journal is not None
                    journaled = True
                    self._journal.write(row.to_json() + "\n")
                    self._journal.flush()
                    self.frames_written += 1
                    self._unsynced.extend(rel for rel in (row.image, row.truth) if rel is not None)
                    batch = self._take_unsynced(SYNC_BATCH)
                    written = True
                self._sync_files(batch)
            except BaseException as e:  # noqa: BLE001 - reported to the reader thread, see module doc
                log.error("recording to %s failed at %s: %s", self.directory, row.image, e)
                if not written:
                    with self._journal_lock:
                        self._writer_dropped += 1  # this frame: its row never went in
                    # Its files (half an image on a full disk) are in no row: free their space, so that
                    # close can still rewrite the manifest with the counters.
                    for rel in (row.image, row.truth) if not journaled else ():
                        if rel is not None:
                            try:
                                (self.directory / rel).unlink(missing_ok=True)
                            except OSError:
                                pass
                self.error = e

    def _take_unsynced(self, at_least: int) -> list[str]:
        """The pending files to fsync, taken off the list, when there are ``at_least`` of them (under the lock)."""
        if len(self._unsynced) < max(at_least, 1):
            return []
        batch, self._unsynced = self._unsynced, []
        return batch

    def _sync_files(self, batch: list[str]) -> None:
        for rel in batch:
            path = self.directory / rel
            _fsync(path)
            with self._journal_lock:
                self._folders.add(path.parent)

    def close(self, counters: dict) -> None:
        """Write what is queued, fsync it (:meth:`_sync`), then finalise the manifest (``complete: true``).
        A submit from another thread after this began raises (:meth:`submit`).

        Its waits (the writers', the fsyncs', the manifest's) end within ``close_timeout_s`` from its start (the
        manifest's gets at least :data:`MANIFEST_WAIT_FLOOR_S`): a disk that stops answering leaves its writer
        threads blocked in a write for good, and a close waiting on them held every stop of the program. Past it
        the take stays ``complete: false``, :attr:`close_timed_out` says why, and the stuck threads are left behind
        (:meth:`lingering`)."""
        self._stopping.set()
        with self._submit_lock:
            pass  # a submit queueing its frame now (it looked before the set) does so ahead of the stop marks
        deadline = time.monotonic() + self.options.close_timeout_s
        if not self._in_thread("rig-recorder-close", self._finish, self.options.close_timeout_s):
            unwritten = self._submitted - self.frames_written - self._writer_dropped  # a snapshot: writers may go on
            self.close_timed_out = RecordingError(
                f"the take's last frames were not written: the disk stopped answering ({unwritten} frame(s) still "
                f"queued or in a write after close_timeout_s={self.options.close_timeout_s:g}; the threads left in "
                f"it: {', '.join(self._threads_in_a_write())})"
            )
            log.error("recording to %s: %s", self.directory, self.close_timed_out)
        self.manifest.complete = self.error is None and self.close_timed_out is None
        self.manifest.counters = dict(counters, frames_written=self.frames_written, writes_dropped=self.writes_dropped)
        if self.close_timed_out is not None:
            self.manifest.counters[CLOSE_TIMED_OUT] = self.options.close_timeout_s
        failure: list[BaseException] = []
        manifest_wait = max(deadline - time.monotonic(), min(MANIFEST_WAIT_FLOOR_S, self.options.close_timeout_s))
        if not self._in_thread("rig-recorder-manifest", lambda: self._write_manifest(failure), manifest_wait):
            log.error("recording to %s: the manifest's last rewrite did not finish within close_timeout_s=%g; it "
                      "says complete: false", self.directory, self.options.close_timeout_s)
            self.close_timed_out = self.close_timed_out or RecordingError(
                f"the take's manifest was not rewritten: the disk stopped answering (close_timeout_s="
                f"{self.options.close_timeout_s:g}); it says complete: false"
            )
        if failure:
            raise failure[0]
        log.info("recording %s closed: %d frames written, %d dropped", self.directory, self.frames_written,
                 self.writes_dropped)

    def _in_thread(self, name: str, work: Callable[[], None], wait_s: float) -> bool:
        """Run ``work`` in a daemon thread, waiting ``wait_s`` for it; False: it is still running (left behind,
        named by :meth:`lingering`)."""
        thread = threading.Thread(target=work, name=name, daemon=True)
        self._close_threads.append(thread)
        thread.start()
        thread.join(wait_s)
        return not thread.is_alive()

    def _write_manifest(self, failure: list[BaseException]) -> None:
        try:
            write_manifest(self.directory, self.manifest)
        except BaseException as e:  # noqa: BLE001 - raised from close, in the caller's thread
            failure.append(e)

    def _finish(self) -> None:
        """The close's writing (in its own thread): the writers' stop marks (a blocking put: the queue may be full
        of frames a stuck writer never takes), their end, the take's fsyncs."""
        for _ in self._threads:
            self._queue.put(None)
        for thread in self._threads:
            thread.join()
        if self._journal is not None:
            try:
                if self.error is None:
                    self._sync()
            except OSError as e:
                log.error("recording to %s: cannot make the take durable: %s", self.directory, e)
                self.error = e
            finally:
                try:
                    self._journal.close()
                except OSError as e:  # flushing what a failed write left buffered (disk full): say so, and
                    # still rewrite the manifest with the counters
                    log.error("recording to %s: cannot close %s: %s", self.directory, FRAMES, e)
                    self.error = self.error or e

    def lingering(self) -> tuple[str, ...]:
        """The recorder's threads still in a write after a close that stopped waiting for them (a dead disk);
        empty once they are out of it, and after a close that did not give up."""
        if self.close_timed_out is None:
            return ()
        return tuple(f"{name} (writing to {shown(str(self.directory))})" for name in self._threads_in_a_write())

    def _threads_in_a_write(self) -> tuple[str, ...]:
        return tuple(t.name for t in (*self._threads, *self._close_threads) if t.is_alive())

    def _sync(self) -> None:
        """fsync the payload files written, their folders and the journal, before ``complete: true`` is written:
        a power cut after the manifest reached the disk must not find the rows' files missing or empty."""
        self._sync_files(self._take_unsynced(1))  # the writers have stopped: what their last batches left
        for folder in sorted(self._folders):
            try:  # makes the files' names durable; not possible on every platform
                _fsync(folder)
            except OSError as e:
                log.debug("recording: fsync of folder %s: %s", folder, e)
        assert self._journal is not None
        self._journal.flush()
        os.fsync(self._journal.fileno())


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class RecordingRigSource(RigSource):
    """Any rig source, recorded as it is read. Build it with ``record+<url>`` (see the module docstring).

    Args:
        inner: the (unopened) source to record.
        options: where and how to record.
    """

    scheme = "record"

    def __init__(self, inner: RigSource, options: RecordOptions, *, source_url: str = "") -> None:
        # The inner source's rig may only be known once it is open (depthai): adopted in _open().
        super().__init__(inner._rig, pairing=inner.pairing, clock=inner.clock)
        self.inner = inner
        self.options = options
        self._source_url = source_url
        self._writer: RecordingWriter | None = None
        self._reported_error = False
        # Set first thing in close: a read in another thread past its wait raises instead of handing out
        # (and queueing) a frame of a closed source; an open in another thread begins no take.
        self._closing = threading.Event()

    @classmethod
    def wrap(cls, inner_url: RigUrl, factory: Callable[..., RigSource], **kwargs) -> "RecordingRigSource":
        """Take the recorder's options out of ``inner_url`` and build the inner source with ``factory``.

        Keyword arguments go to the inner backend, except ``out`` (the recording directory).
        """
        options = RecordOptions.take_from(inner_url, kwargs.pop("out", None))
        text = inner_url_text(inner_url)
        return cls(factory(text, **kwargs), options, source_url=text)

    @classmethod
    def from_url(cls, url: RigUrl, **kwargs) -> "RecordingRigSource":
        raise RigConfigError(
            f"rig URL {url.url!r}: the recorder wraps another URL: write record+<url>, e.g. record+sim://?out=DIR"
        )

    @property
    def stats(self) -> RecordingStats:
        base = super().stats
        writer = self._writer
        return RecordingStats(
            **vars(base),
            frames_written=writer.frames_written if writer else 0,
            writes_dropped=writer.writes_dropped if writer else 0,
        )

    def log_rig_warnings_once(self, logged: set[str]) -> None:
        super().log_rig_warnings_once(logged)
        self.inner.log_rig_warnings_once(logged)  # the inner source builds the rig and warns of it

    def warn_of_built_rig(self) -> None:
        self.inner.warn_of_built_rig()  # the inner source builds the rig

    def _open(self) -> None:
        try:
            self.inner.open()
        except RigOperationError as e:
            # closed (see close) before the inner open began, which refused a closed source ("was closed; open a
            # new source"): this open is the one cancelled. A camera of another size (FrameSizeError) stays as it is.
            if self._closing.is_set() and not isinstance(e, RigInitializationError):
                raise self._cancelled_open() from e
            raise
        try:
            if self._closing.is_set():  # closed (see close) as the inner source finished opening: no take to start
                raise self._cancelled_open()
            self.pairing = self.inner.pairing  # an inner source may settle its pairing at open (opencv://)
            self._set_rig(self.inner.rig)
            manifest = Manifest(
                rig=self.inner.rig,
                image_format=self.options.image_format,
                source=redact_url(self._source_url),  # a take is shared: never a stream's password
                created_utc=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            )
            self._writer = RecordingWriter(self.options.out, manifest, self.options)
            self._writer.start()
        except BaseException:
            self.inner.close()
            raise

    def _cancelled_open(self) -> RigInitializationError:
        """What :meth:`open` raises when a :meth:`close` from another thread landed in it."""
        return RigInitializationError(f"record+ source closed while it opened (a close() from another thread): the "
                                      f"open was cancelled, no take started in {shown(str(self.options.out))}")

    def _read_frame(self, timeout_s: float) -> Frame | None:
        writer = self._writer
        assert writer is not None
        if writer.error is not None and not self._reported_error:
            self._reported_error = True
            raise RecordingError(f"recording to {shown(str(writer.directory))} failed: "
                                 f"{writer.error}") from writer.error
        frame = self.inner._read_frame(timeout_s)
        if frame is None:
            return None
        if self._closing.is_set():
            raise RigOperationError(f"record+ source closed while a read waited for its frame (recording to "
                                    f"{shown(str(writer.directory))}); the frame is not recorded")
        writer.submit(frame)  # raises if the close began meanwhile (lossless: while it waited for a slot)
        return frame

    def unreported_failure(self) -> str | None:
        """The take's write error that no ``read()`` raised (a frame still queued at close, the take's last fsync,
        a close past ``close_timeout_s``), for a caller to report once the source is closed: the take's manifest says
        ``complete: false``. ``None`` where the take has no error, or a read raised it as :class:`RecordingError`."""
        writer = self._writer
        if writer is not None and writer.close_timed_out is not None:  # whatever a read raised before: it is new
            return (f"recording to {shown(str(writer.directory))} failed as it closed: {writer.close_timed_out}; its "
                    f"manifest says complete: false")
        if writer is None or writer.error is None or self._reported_error:
            return None
        return (f"recording to {shown(str(writer.directory))} failed as it closed: {writer.error}; its manifest says "
                f"complete: false")

    def _frame_available(self) -> bool:
        return self.inner._frame_available()  # drained frames pass through _read_frame, so they are recorded

    @property
    def drain_limit(self) -> int:  # type: ignore[override]
        return self.inner.drain_limit  # what the inner source can hold; its _catch_up is not used: all is recorded

    @property
    def live_timestamps(self) -> bool:  # type: ignore[override]
        return self.inner.live_timestamps  # frames pass through with the inner source's stamps

    def _pairs_lost(self) -> int:
        return self.inner._pairs_lost()

    def lingering(self) -> tuple[str, ...]:
        # its cameras' calls, then the writers a close past close_timeout_s left in a write (a dead disk)
        return self.inner.lingering() + (self._writer.lingering() if self._writer is not None else ())

    def _cancel_open(self) -> None:
        self._closing.set()  # no take is begun
        self.inner.close()  # cancels the inner source's open, as closing it would

    def _close(self) -> None:
        self._closing.set()
        try:
            self.inner.close()
        finally:
            if self._writer is not None:
                counters = dict(vars(super().stats))
                # backend-specific counters (e.g. the simulator's drops) of the inner source
                pairing_fields = set(vars(PairingStats()))
                counters["inner"] = {k: v for k, v in vars(self.inner.stats).items() if k not in pairing_fields}
                self._writer.close(counters)
