"""On-disk sample cache: ``.npy`` shards, one folder per split, read a sample's rows at a time.

Layout::

    <root>/dataset.json                  manifest: format, schema version, generator version,
                                         resolution, view names, source config, per-split spec
                                         and count
    <root>/<split>/shard_000000/         samples [0, shard_size)
        images.npy  masks.npy  ...       one array per entry of ``sample.FIELDS``, stacked over
                                         the shard's samples (leading axis)
        meta.json                        {"first_index", "count", "samples": [metadata...],
                                          "crc32": {array name: [CRC-32 of each stored sample's slice]}}
    <root>/<split>/shard_000001/ ...
    <root>/dataset.lock                  the one writer's lock (``writer_lock``; its pid line and identity
                                         while held)

A shard folder is written under a temporary name, fsynced, and renamed when complete, so a
folder named ``shard_*`` is always whole, a power cut included; an interrupted run leaves only
``*.tmp-*`` folders, which the next run deletes. Shard ``k`` holds samples
``[k * shard_size, min((k + 1) * shard_size, count))``; since samples are deterministic per
index, a larger ``count`` regenerates only the missing or short shards. After a smaller ``count``
(``generate`` asked for fewer) the last shard may hold more samples than the split's: readers use
its first ones, and the shards past the count stay on disk unread (a larger count reuses them).

Reading: opening a split reads the manifest, the shards' ``meta.json`` and each array file's
header and size (a damaged shard is named then, not inside a DataLoader worker); a sample costs
one positioned read (``os.preadv``) of its slice of each array, into the array the caller gets.
Not memory maps: a file cut short after the split opened (another process truncating or
rewriting it) gives a short read, a ``DatasetError`` naming the file and the sample, where a
mapped page past the new end killed the process (or a DataLoader worker) with SIGBUS. At most
``max_open_shards`` shards stay open (LRU), bounding file descriptors.

Checksums: ``write_shard`` records the CRC-32 of each sample's slice of each array (``CHECKSUMS`` in
``meta.json``), and reading a sample checks the slices it copies anyway (no extra disk read; 0.25-0.5 ms of
CPU a 128 px sample, ``docs/dataset.md``), so a flipped bit is named when it is read, never trained on;
``training.data.verify`` checks a whole dataset. Shards written before the checksums have none: they are read
unchecked, and opening a split says once how many of its shards that is.
"""
from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import shutil
import socket
import time
import zlib
from collections import OrderedDict
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from ghnerf_runtime.plain_values import numpy_for_json
from training.data.errors import DatasetError
from training.data.sample import FIELDS, Sample, arrays_to_sample, sample_to_arrays
from training.run_lock import is_recorded_process, process_identity

log = logging.getLogger(__name__)

FORMAT = "ghnerf-multiview"
SCHEMA_VERSION = 1
MANIFEST = "dataset.json"
SHARD_META = "meta.json"
#: Held (``flock``) by the one process writing a dataset folder, which writes its pid line into it (``writer_lock``).
WRITER_LOCK = "dataset.lock"
#: Key of a shard's ``meta.json`` holding ``{array name: [CRC-32 of each stored sample's slice, in order]}``:
#: one checksum per sample, so a read checks the bytes it reads and nothing more.
CHECKSUMS = "crc32"


def shard_name(k: int) -> str:
    return f"shard_{k:06d}"


# ------------------------------------------------------------------ manifest
def read_manifest(root: str | Path) -> dict:
    """The manifest of the dataset at ``root``; :class:`DatasetError` names the file when it is bad."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise DatasetError(path, "no dataset manifest here (not a dataset folder, or generation never started)")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(path, f"unreadable manifest: {e}") from e
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise DatasetError(path, f"not a {FORMAT} manifest (format {manifest.get('format') if isinstance(manifest, dict) else None!r})")
    version = manifest.get("schema_version")
    if version != SCHEMA_VERSION:
        newer = _is_count(version) and version > SCHEMA_VERSION
        raise DatasetError(path, f"schema_version {version!r}; this code reads {SCHEMA_VERSION}" + (
            ": the dataset was written by a newer version of this code; update the code, or generate the dataset "
            "again with this one into a new folder" if newer else ""))
    for key in ("resolution", "view_names", "splits"):
        if key not in manifest:
            raise DatasetError(path, f"manifest lacks {key!r}")
    _check_manifest_fields(manifest, path)
    return manifest


def _check_manifest_fields(manifest: dict, path: Path) -> None:
    # readers index these fields directly: a hand-edited or damaged manifest must fail here, named
    res, names, splits = manifest["resolution"], manifest["view_names"], manifest["splits"]
    if isinstance(res, bool) or not isinstance(res, int) or res < 1:
        raise DatasetError(path, f"resolution must be a positive int, got {res!r}")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise DatasetError(path, f"view_names must be a list of names, got {names!r}")
    if not isinstance(splits, dict):
        raise DatasetError(path, f"splits must be a mapping of split name to entry, got {splits!r}")
    for name, info in splits.items():
        if not isinstance(info, dict):
            raise DatasetError(path, f"splits.{name} must be a mapping, got {info!r}")
        for key, lo in (("count", 0), ("shard_size", 1)):
            v = info.get(key)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise DatasetError(path, f"splits.{name}.{key} must be an int >= {lo}, got {v!r}")


#: The version a manifest without ``generator_version`` was made by: every cache written before the field existed.
UNVERSIONED_GENERATOR = 1


def generator_version(manifest: Mapping[str, Any]) -> int:
    """The version of the code that rendered the samples of ``manifest`` (``generate.GENERATOR_VERSION``)."""
    return manifest.get("generator_version", UNVERSIONED_GENERATOR)


def write_manifest(root: str | Path, manifest: dict) -> None:
    """Replace ``root``'s manifest atomically and durably (a power cut leaves the old one or the new one).

    Raises:
        DatasetError: the write failed (a full disk says so); the old manifest is left as it was.
    """
    path = Path(root) / MANIFEST
    try:
        _replace_text(path, json.dumps(manifest, indent=1, sort_keys=True))
    except OSError as e:
        raise _write_error(path, "the manifest", e) from e


def _replace_text(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` through a fsynced temporary file and a fsynced rename (a power cut leaves the
    old file or the new one); a failed write removes the temporary file and raises its OSError."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:  # a Ctrl-C or SIGTERM (generate's Terminated) in the write too: no manifest.json.tmp left
        tmp.unlink(missing_ok=True)
        raise


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable: without it a power cut can undo the rename after later writes
    reached the disk."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_error(path: Path, what: str, e: OSError) -> DatasetError:
    if e.errno in (errno.ENOSPC, errno.EDQUOT):
        return DatasetError(path, f"no space left on the device (or quota) writing {what} of dataset "
                                  f"{path.parent if what == 'the manifest' else path.parent.parent}: nothing partial "
                                  "was kept; free space, then run the same command again (it resumes)")
    return DatasetError(path, f"could not write {what}: {e}; nothing partial was kept")


def new_manifest(*, resolution: int, view_names: Sequence[str], source: str, source_config: dict) -> dict:
    return {"format": FORMAT, "schema_version": SCHEMA_VERSION, "resolution": int(resolution),
            "view_names": list(view_names), "num_sources": 2, "image_channels": "RGB", "source": source,
            "source_config": source_config, "splits": {}}


# ------------------------------------------------------------------ writing
@contextmanager
def writer_lock(root: str | Path) -> Iterator[None]:
    """Be the only writer of the dataset folder ``root`` while the block runs.

    Two writers at once break a folder: each one's start deletes the other's unfinished ``*.tmp-*`` shards
    (taken for a crash's leftovers), a shard renamed over one being renamed fails, and both rewrite the
    manifest from what they read before (the last one drops the other's splits). So a second writer is
    refused, naming the lock file and the holder (its pid, host and start, which the holder writes into the
    file, then on a second line its identity, ``training.run_lock``). The lock goes with the process
    (``flock``): a killed writer leaves none behind, so there is no stale lock to clear; a killed one's pid
    line is stale but harmless, and a number since given to another process is not named as the holder (the
    identity differs). The file is emptied on the way out (two folders made alike stay byte-identical).

    Raises:
        DatasetError: another process holds the lock.
    """
    path = Path(root) / WRITER_LOCK
    fh = open(path, "a+")
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(path, _held_message(Path(root), path)) from None
        fh.truncate(0)
        fh.write(_holder_text())
        fh.flush()
        try:
            yield
        finally:
            fh.truncate(0)
    finally:
        fh.close()  # releases the lock


def _holder_text() -> str:
    """What the holder writes into the lock file: ``<pid> <host> <start>``, then its identity
    (``run_lock.process_identity``) on a second line where ``/proc`` gives one."""
    pid = os.getpid()
    line = f"{pid} {socket.gethostname()} {time.strftime('%Y-%m-%dT%H:%M:%S%z')}\n"
    identity = process_identity(pid)
    return f"{line}{identity}\n" if identity else line


def _read_holder(path: Path) -> tuple[int, str, str, str | None]:
    """The pid, host, start and identity that the holder wrote into ``path`` (identity None in a file of the older
    one-line form). Raises OSError or ValueError where the file does not say (empty, not written yet)."""
    lines = path.read_text().splitlines()
    if not lines:
        raise ValueError(f"{path} is empty")
    pid_s, host, since = lines[0].split()
    recorded = lines[1].strip() if len(lines) > 1 else ""
    return int(pid_s), host, since, recorded or None


def _holder_alive(pid: int, recorded: str | None) -> bool:
    """Whether the process that wrote the lock line (number ``pid``, identity ``recorded``) still runs here."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process: alive, and the identity says whether it is the holder
        pass
    # a killed holder's number may since belong to another process: not the holder, and not one to kill
    return is_recorded_process(pid, recorded)


def _held_message(root: Path, path: Path) -> str:
    """Why ``root`` is refused, naming the holder when its line in ``path`` says who it is."""
    head = f"another process holds this lock: it is writing dataset {root} (generate or a conversion)"
    try:
        pid, host, since, recorded = _read_holder(path)
    except (OSError, ValueError):  # an older writer's empty file, or the holder has not written its line yet
        return (f"{head}; wait for it to finish, then run the command again (it resumes); `fuser -v {path}` "
                "names the holder on this machine")
    if host != socket.gethostname():
        return (f"{head}: pid {pid} on host {host}, since {since}. Wait for it or stop it there, then run the "
                "command again (it resumes); the lock is released when that process ends, or by the file "
                f"server when {host} is down")
    if _holder_alive(pid, recorded):
        return (f"{head}: pid {pid}, since {since}. Wait for it to finish or stop it (kill {pid}), then run the "
                "command again (it resumes); the lock is released when that process ends, nothing to delete")
    return (f"{head}: pid {pid} (since {since}) has ended, but a process it started still holds the lock; "
            f"`fuser -v {path}` names it: stop it, then run the command again (it resumes)")


def write_shard(folder: str | Path, samples: Sequence[Sample], first_index: int) -> Path:
    """Write ``samples`` (indices ``first_index ..``) as the complete shard ``folder`` (atomic rename).

    Every file is fsynced before the rename, and the rename itself after it: a power cut leaves the
    old shard, no shard, or the whole new one, never a ``shard_*`` folder of empty or short files.
    A failed write (a full disk) removes what it wrote.

    Raises:
        DatasetError: the write failed; it names the shard and, on a full disk, says so.
    """
    folder = Path(folder)
    if not samples:
        raise ValueError("a shard needs at least one sample")
    tmp = folder.with_name(f"{folder.name}.tmp-{os.getpid()}")
    try:
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        records = [sample_to_arrays(s) for s in samples]
        checksums = {}
        for name in FIELDS:
            stacked = np.stack([r[name] for r in records])
            checksums[name] = row_checksums(stacked)  # of the bytes np.save writes (C order, row by row)
            with open(tmp / f"{name}.npy", "wb") as fh:
                np.save(fh, stacked)
                fh.flush()
                os.fsync(fh.fileno())
        meta = {"first_index": int(first_index), "count": len(samples), "samples": [s.metadata for s in samples],
                CHECKSUMS: checksums}
        with open(tmp / SHARD_META, "w") as fh:
            fh.write(json.dumps(meta, default=numpy_for_json))
            fh.flush()
            os.fsync(fh.fileno())
        _fsync_dir(tmp)
        if folder.exists():
            shutil.rmtree(folder)
        os.replace(tmp, folder)
        _fsync_dir(folder.parent)
    except OSError as e:
        shutil.rmtree(tmp, ignore_errors=True)  # on a full disk above all: a partial shard would hold space
        raise _write_error(folder, "this shard", e) from e
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def row_checksums(array: np.ndarray) -> list[int]:
    """The CRC-32 of each ``array[j]`` (one sample's slice; the rows of a C-contiguous array, as ``np.save`` writes
    them)."""
    return [zlib.crc32(row) for row in array]


def _checksums(meta: dict, meta_path: Path, stored: int) -> dict[str, np.ndarray] | None:
    """The per-sample checksums of a shard's ``meta.json`` (``None``: written before they were recorded).

    Raises:
        DatasetError: the entry is there but malformed (an array missing, a count that is not the shard's).
    """
    entry = meta.get(CHECKSUMS)
    if entry is None:
        return None
    if not isinstance(entry, dict):
        raise DatasetError(meta_path, f"{CHECKSUMS} must map each array to its samples' checksums, got "
                                      f"{type(entry).__name__}")
    out = {}
    for name in FIELDS:
        sums = entry.get(name)
        if not isinstance(sums, list) or len(sums) != stored or not all(
                _is_count(c) and 0 <= c < 1 << 32 for c in sums):
            raise DatasetError(meta_path, f"{CHECKSUMS}.{name} must be {stored} CRC-32 values (one per stored "
                                          f"sample), got {str(sums)[:80]}")
        out[name] = np.array(sums, dtype=np.uint32)  # (a run's many shards: 4 bytes each, not a Python int)
    return out


def repair_hint(manifest: Mapping[str, Any], root: Path, split: str, folder: Path) -> str:
    """What to do about damaged shard ``folder``: make it again the way its dataset was made."""
    if manifest.get("source") == "synthetic":
        return (f"delete {folder} and run the same `python -m training.data.generate --out {root} ...` command "
                "again: it renders the missing shard alone")
    if manifest.get("source") == "zju":
        return (f"convert split {split!r} again (`python -m training.data.convert_zju SUBJECT --out {root} --split "
                f"{split} ...`): it rewrites the split")
    return f"write split {split!r} again"


def shard_plan(count: int, shard_size: int) -> list[tuple[int, int, int]]:
    """``(k, first_index, n)`` of every shard of a split of ``count`` samples."""
    return [(k, i0, min(shard_size, count - i0)) for k, i0 in enumerate(range(0, count, shard_size))]


def shard_is_complete(folder: Path, first_index: int, count: int, *, max_count: int | None = None) -> bool:
    """Whether ``folder`` is a whole shard of samples ``first_index ..`` holding ``count`` of them, or up to
    ``max_count`` (the split's shard size): a shard of a larger count of the split holds the same first ones."""
    meta = folder / SHARD_META
    if not meta.is_file():
        return False
    try:
        data = json.loads(meta.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    if not isinstance(data, dict):  # damaged: render the shard again
        return False
    if not (data.get("first_index") == first_index and _serves(data.get("count"), count, max_count or count)):
        return False
    try:
        _checksums(data, folder / SHARD_META, data["count"])
    except DatasetError:  # damaged checksums: the shard would be refused when read
        return False
    # (a shard of older code, with no checksums, is kept: rendering it again would cost hours for nothing)
    return all(_array_is_whole(folder / f"{name}.npy") for name in FIELDS)


def _is_count(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _serves(stored: object, count: int, max_count: int) -> bool:
    """Whether a shard whose metadata says it stores ``stored`` samples serves ``count`` of them: exactly that many,
    or up to ``max_count`` (the split's shard size: the last shard of a split generated larger, then asked
    smaller, holds more, and its first ``count`` are the split's)."""
    return _is_count(stored) and count <= stored <= max(count, max_count)  # type: ignore[operator]


def stored_count(folder: Path) -> int:
    """The samples shard ``folder``'s metadata says it holds (0 when it is missing or unreadable)."""
    try:
        count = json.loads((folder / SHARD_META).read_text()).get("count")
    except (OSError, json.JSONDecodeError, AttributeError):
        return 0
    return count if _is_count(count) else 0


def _array_is_whole(path: Path) -> bool:
    """``path`` is a .npy file as long as its header says (a cut one is rendered again on resume): numpy maps
    it only then (an empty file: EOFError; a short one: ValueError)."""
    try:
        np.load(path, mmap_mode="r")
        return True
    except (OSError, ValueError, EOFError):
        return False


def remove_stale_temporaries(split_dir: Path) -> None:
    for tmp in split_dir.glob("shard_*.tmp-*"):
        log.info("removing interrupted shard %s", tmp)
        shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------ reading
def _check_array_file(path: Path, shape: tuple[int, ...], dtype: np.dtype) -> None:
    """``path`` is a whole ``.npy`` of ``shape`` and ``dtype``, from its header and its size (no data read).

    Checked when a split opens, in the process that opens it: a cut or wrong file found only when a sample
    of it is read would stop a training run midway, inside a DataLoader worker (which turns the error into a
    RuntimeError holding a traceback).
    """
    _ArrayRows(path, shape, dtype).close()


class _PastEnd(Exception):
    """A row reaches past the end of its file: the file was cut after it was checked."""

    def __init__(self, size: int, end: int) -> None:
        super().__init__(f"the file holds {size} bytes, the row ends at byte {end}")
        self.size, self.end = size, end


class _ArrayRows:
    """One stored array file, open, read one row (one sample's slice) at a time by positioned reads.

    Not memory-mapped: a file cut short after it was checked (another process truncating or rewriting it in
    place) then gives a short read, which becomes a named error, where touching a mapped page past the new end
    of the file killed the process with SIGBUS (a DataLoader worker too). Positioned reads leave the file offset
    alone, so DataLoader workers forked with the file open share it safely.

    Raises (on open):
        DatasetError: the file is missing, its header unreadable, of another shape or dtype, or its size is
            not the header's (named).
    """

    def __init__(self, path: Path, shape: tuple[int, ...], dtype: np.dtype) -> None:
        self.path = path
        try:
            self._file = open(path, "rb", buffering=0)
        except FileNotFoundError:
            raise DatasetError(path, "missing from its shard (regenerate or resume)") from None
        except OSError as e:
            raise DatasetError(path, f"unreadable array: {e}") from e
        try:
            self._data_at = self._check(shape, dtype)
        except BaseException:
            self._file.close()
            raise
        self.row_shape, self.dtype = tuple(shape[1:]), dtype
        self.row_bytes = int(np.prod(self.row_shape, dtype=np.int64)) * dtype.itemsize

    def _check(self, shape: tuple[int, ...], dtype: np.dtype) -> int:
        """The offset of the data, once the header and the size are the expected ones."""
        fh, path = self._file, self.path
        try:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                got_shape, fortran, got_dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                got_shape, fortran, got_dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            data_at = fh.tell()
            size = os.fstat(fh.fileno()).st_size
        except (OSError, ValueError, EOFError) as e:  # EOFError / ValueError: an empty or cut header
            raise DatasetError(path, f"unreadable array: {e or type(e).__name__}") from e
        if tuple(got_shape) != tuple(shape) or got_dtype != dtype or fortran:
            raise DatasetError(path, f"has shape {tuple(got_shape)} {got_dtype}, expected {tuple(shape)} {dtype}")
        want = data_at + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if size != want:
            raise DatasetError(path, f"holds {size} bytes, its header says {want}: the file is cut short or damaged "
                                     "(regenerate, or resume: generate renders such a shard again)")
        return data_at

    def row(self, j: int) -> np.ndarray:
        """A new array holding row ``j``, read from the file now.

        Raises:
            _PastEnd: the file ends before the row does (cut after it was checked).
            OSError: the read failed (a bad disk).
        """
        out = np.empty(self.row_shape, self.dtype)
        buf = out.reshape(-1).view(np.uint8)  # (writes into ``out``: no second copy)
        at, got = self._data_at + j * self.row_bytes, 0
        while got < self.row_bytes:  # a regular file reads short only at its end; loop all the same
            n = _pread_into(self._file.fileno(), buf[got:], at + got)
            if n == 0:
                raise _PastEnd(os.fstat(self._file.fileno()).st_size, at + self.row_bytes)
            got += n
        return out

    def close(self) -> None:
        self._file.close()


def _pread_into(fd: int, buf: np.ndarray, offset: int) -> int:
    """Read into ``buf`` from byte ``offset`` of ``fd`` without moving its offset; the bytes read."""
    if hasattr(os, "preadv"):
        return os.preadv(fd, [buf], offset)
    data = os.pread(fd, len(buf), offset)  # (a platform without preadv: one copy more)
    buf[:len(data)] = np.frombuffer(data, np.uint8)
    return len(data)


@dataclass(frozen=True)
class ShardInfo:
    """One shard of a split, as its ``meta.json`` and its arrays' headers describe it."""

    folder: Path
    first_index: int
    count: int  # the samples of the split in it
    stored: int  # the samples in its files: more than count in the last shard of a split made smaller
    metadata: list
    checksums: dict[str, np.ndarray] | None  # per array, one CRC-32 per stored sample; None: written without
    shapes: dict[str, tuple[int, ...]]  # per array, the file's shape (stored samples first), as checked

    def array_rows(self, name: str) -> "_ArrayRows":
        """Array ``name`` of this shard, open (its header and size checked again: it may have changed since)."""
        return _ArrayRows(self.folder / f"{name}.npy", self.shapes[name], FIELDS[name][1])


def scan_shard(split_dir: Path, k: int, first: int, n: int, shard_size: int, num_views: int,
               resolution: int) -> ShardInfo:
    """Shard ``k`` of ``split_dir`` (samples ``first .. first + n - 1``), checked from its metadata and its
    arrays' headers and sizes (no sample data read).

    Raises:
        DatasetError: the metadata or an array is missing, malformed, of the wrong shape or cut short (named).
    """
    folder = split_dir / shard_name(k)
    meta_path = folder / SHARD_META
    if not meta_path.is_file():
        raise DatasetError(meta_path, f"missing: split {split_dir.name!r} should hold shard {k} = samples "
                                      f"{first}..{first + n - 1}; regenerate or resume")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(meta_path, f"unreadable shard metadata: {e}") from e
    if not isinstance(meta, dict) or not isinstance(meta.get("samples", []), list):
        raise DatasetError(meta_path, "shard metadata must be a JSON object with first_index, count and a "
                                      f"samples list, got {type(meta).__name__}")
    stored = meta.get("count")
    if meta.get("first_index") != first or not _serves(stored, n, shard_size) \
            or len(meta.get("samples", [])) != stored:
        want = f"{first} x {n}" if n == shard_size else f"{first} x {n} to {shard_size}"
        raise DatasetError(meta_path, f"shard holds samples from {meta.get('first_index')} x {meta.get('count')}, "
                                      f"expected {want}")
    shapes = {name: (stored, *shape_fn(num_views, resolution)) for name, (shape_fn, _) in FIELDS.items()}
    for name, (_, dtype) in FIELDS.items():
        _check_array_file(folder / f"{name}.npy", shapes[name], dtype)
    return ShardInfo(folder, first, n, stored, meta["samples"][:n], _checksums(meta, meta_path, stored), shapes)


def damaged_rows(shard: ShardInfo) -> dict[str, list[int]]:
    """Per array of ``shard``, the stored rows whose bytes differ from their recorded checksum (reads the whole
    shard; ``{}`` when it is whole or has no checksums).

    Raises:
        DatasetError: an array file cannot be read (named).
    """
    if shard.checksums is None:
        return {}
    bad = {}
    for name in FIELDS:
        got = _file_checksums(shard, name)
        rows = [j for j, (a, b) in enumerate(zip(got, shard.checksums[name])) if a != int(b)]
        if rows:
            bad[name] = rows
    return bad


def record_missing_checksums(shard: ShardInfo) -> bool:
    """Give ``shard``, written before checksums were recorded, the checksums of its arrays as they are now (their
    damage, if any, is then taken for data: check such a shard by other means first if you doubt it). The caller
    holds :func:`writer_lock`. Returns whether it wrote them (``False``: the shard had them).

    Raises:
        DatasetError: the metadata could not be rewritten (the old one is kept), or an array cannot be read.
    """
    if shard.checksums is not None:
        return False
    meta_path = shard.folder / SHARD_META
    meta = json.loads(meta_path.read_text())
    sums = {name: _file_checksums(shard, name) for name in FIELDS}
    meta[CHECKSUMS] = sums
    try:
        _replace_text(meta_path, json.dumps(meta, default=numpy_for_json))
    except OSError as e:
        raise _write_error(meta_path, "this shard's metadata", e) from e
    return True


def _file_checksums(shard: ShardInfo, name: str) -> list[int]:
    """The CRC-32 of each stored row of ``shard``'s array ``name``, read a row at a time (no whole shard in memory,
    no map: a file cut meanwhile is named, not a SIGBUS).

    Raises:
        DatasetError: the file is unreadable, not as scanned, or cut while it is read (named).
    """
    path = shard.folder / f"{name}.npy"
    rows = shard.array_rows(name)
    try:
        return [zlib.crc32(rows.row(j)) for j in range(shard.stored)]
    except _PastEnd as e:
        raise DatasetError(path, f"{e}: it was cut short while being read; run the check again") from None
    except OSError as e:
        raise DatasetError(path, f"unreadable array: {e}") from e
    finally:
        rows.close()


class ShardedSplit:
    """Read-only, random-access view of one split of a cached dataset (numpy, torch-free).

    Args:
        root: the dataset folder (holding ``dataset.json``).
        split: split name (``"train"``, ``"val"``...).
        max_open_shards: shards whose array files are kept open at once (at least the one being read).

    Raises:
        DatasetError: the manifest, a shard folder, an array file or its shape is missing or
            wrong; the message names the file.
    """

    def __init__(self, root: str | Path, split: str, *, max_open_shards: int = 16) -> None:
        self.root = Path(root)
        self.manifest = read_manifest(self.root)
        splits = self.manifest["splits"]
        if split not in splits:
            raise DatasetError(self.root / MANIFEST, f"has no split {split!r}; splits: {sorted(splits)}")
        self.split = split
        self.info = splits[split]
        if not self.info["count"]:  # every reader would see no scene: training would start and learn nothing
            raise DatasetError(self.root / MANIFEST, f"split {split!r} holds no samples (count 0); generate it "
                                                     "with a count above 0")
        self.resolution = int(self.manifest["resolution"])
        self.view_names = tuple(self.manifest["view_names"])
        self.num_views = len(self.view_names)
        self._max_open = int(max_open_shards)
        self._open: OrderedDict[int, dict[str, _ArrayRows]] = OrderedDict()
        count, shard_size = int(self.info["count"]), int(self.info["shard_size"])
        self._shards = [scan_shard(self.root / split, k, i0, n, shard_size, self.num_views, self.resolution)
                        for k, i0, n in shard_plan(count, shard_size)]
        self._starts = np.array([s.first_index for s in self._shards], dtype=np.int64)
        bare = sum(s.checksums is None for s in self._shards)
        if bare:  # one note per split opened, not one per shard or per read
            log.warning("%s split %r: %d of its %d shards carry no checksums (written before they were recorded): "
                        "damage inside their arrays is not detected; `python -m training.data.verify %s "
                        "--record-missing` records them", self.root, split, bare, len(self._shards), self.root)

    def __len__(self) -> int:
        return int(self.info["count"])

    def _locate(self, index: int) -> tuple[int, int]:
        if not -len(self) <= index < len(self):
            raise IndexError(f"index {index} out of range for split {self.split!r} of {len(self)} samples")
        index %= len(self)
        k = int(np.searchsorted(self._starts, index, side="right") - 1)
        return k, index - self._shards[k].first_index

    def _files(self, k: int) -> dict[str, _ArrayRows]:
        if k in self._open:
            self._open.move_to_end(k)
            return self._open[k]
        shard, files = self._shards[k], {}
        try:
            for name in FIELDS:
                files[name] = shard.array_rows(name)
        except DatasetError:
            for f in files.values():
                f.close()
            raise
        self._open[k] = files
        while len(self._open) > max(self._max_open, 1):  # (the shard about to be read stays open: it is the last)
            for f in self._open.popitem(last=False)[1].values():
                f.close()
        return files

    def arrays(self, index: int) -> dict[str, np.ndarray]:
        """The stored record of sample ``index`` (new arrays; masks still bit-packed), checked against the checksums
        its shard recorded.

        Raises:
            DatasetError: a slice's bytes differ from its checksum, or its file was cut short (or could not be
                read) after the split opened; names the array file, the sample and how to make the shard again.
        """
        k, j = self._locate(index)
        shard = self._shards[k]
        out = {}
        for name, rows in self._files(k).items():
            try:
                row = rows.row(j)  # the copy the caller gets: checking it reads nothing more from the disk
            except _PastEnd as e:
                raise DatasetError(rows.path, self._cut_message(shard, j, e)) from None
            except OSError as e:  # a bad disk: EIO
                raise DatasetError(rows.path, f"sample {shard.first_index + j} (row {j} of the shard) could not "
                                              f"be read: {e}") from e
            if shard.checksums is not None:
                got, want = zlib.crc32(row), int(shard.checksums[name][j])
                if got != want:
                    raise DatasetError(rows.path, self._damage_message(shard, j, got, want))
            out[name] = row
        return out

    def _cut_message(self, shard: ShardInfo, j: int, e: _PastEnd) -> str:
        return (f"sample {shard.first_index + j} (row {j} of the shard) is past the file's end ({e}): the file was "
                "cut short after the split was opened (another process copying over it or rewriting it in place "
                f"while the run reads it). {repair_hint(self.manifest, self.root, self.split, shard.folder)}; "
                f"`python -m training.data.verify {self.root}` lists every damaged shard")

    def _damage_message(self, shard: ShardInfo, j: int, got: int, want: int) -> str:
        return (f"sample {shard.first_index + j} (row {j} of the shard) does not match its checksum: CRC-32 "
                f"{got:08x}, {SHARD_META} recorded {want:08x}; the file changed after it was written (a bad disk, "
                f"an interrupted copy). {repair_hint(self.manifest, self.root, self.split, shard.folder)}; "
                f"`python -m training.data.verify {self.root}` lists every damaged shard")

    def metadata(self, index: int) -> dict:
        k, j = self._locate(index)
        return self._shards[k].metadata[j]

    def all_metadata(self) -> Iterator[dict]:
        for shard in self._shards:
            yield from shard.metadata

    def __getitem__(self, index: int) -> Sample:
        return arrays_to_sample(self.arrays(index), self.view_names, self.metadata(index))

    def __getstate__(self) -> dict:
        # Open files do not pickle (DataLoader workers with spawn): reopen lazily.
        state = self.__dict__.copy()
        state["_open"] = OrderedDict()
        return state


__all__ = ["FORMAT", "SCHEMA_VERSION", "MANIFEST", "WRITER_LOCK", "CHECKSUMS", "UNVERSIONED_GENERATOR",
           "generator_version", "ShardedSplit", "ShardInfo", "scan_shard", "row_checksums", "damaged_rows",
           "record_missing_checksums", "repair_hint", "read_manifest", "write_manifest", "new_manifest", "writer_lock",
           "write_shard", "shard_plan", "shard_name", "shard_is_complete", "stored_count", "remove_stale_temporaries"]
