"""``ModelSession``: owns onnxruntime for one exported model; knows nothing of joints.

Running the model is kept apart from interpreting its outputs (frigate's
``BaseModelRunner`` vs its detectors): the session loads the graph files, checks
them against the model contract, warms them up and runs them by name; the
:class:`~ghnerf_runtime.estimator.Estimator` is handed a session and does the rest.

Model folder layout (what ``python -m training.export`` writes)::

    <model_dir>/<graph>.onnx          fp32, one file per graph (encoder, volume, render_heat, ...)
    <model_dir>/<graph>.int8.onnx     static int8 QDQ, where the exporter made one
    <model_dir>/model_card.json       optional: training figures; read and kept, never required
    <model_dir>/skeleton_prior.onnx   optional: the learnt skeleton prior (its own metadata,
                                      ghnerf_runtime.skeleton_prior), loaded on request
    <model_dir>/novel_painter.onnx    optional: the novel view's learnt painter (its own metadata,
                                      ghnerf_runtime.novel_painter), loaded on request; its int8 twin
                                      novel_painter.int8.onnx where the precision allows

The shipped layout (``python -m training.pipeline --out models/``) puts each variant in a
subfolder, ``models/ghnerf/`` and ``models/baseline/``, with ``models/model_card.json`` beside
them: a ``model_dir`` holding no graph files but a ``ghnerf/`` subfolder (or a single subfolder
with graphs) resolves to it, and the card is looked up in the folder, then its parent
(:func:`resolve_model_dir`). Files whose names do not follow the pattern are found by their
metadata (``ghnerf.graph`` / ``ghnerf.precision``) when the conventional name is missing.

What is checked at load (each failure names the file and what is wrong):

* the file is a readable ONNX model (:class:`ModelLoadError` for a missing, truncated or
  corrupt file);
* its ``ghnerf.*`` metadata parses into a :class:`~ghnerf_runtime.contract.ModelContract`
  of a compatible contract version (:class:`ModelContractError` naming the key);
* it holds the graph it is loaded as, and its inputs/outputs match the contract's names and
  fixed dimensions (``ModelContract.check_io``), all float32;
* every graph file of the model carries the same contract (same model, same version);
* the graph files that carry a weights id (``ghnerf.weights_id``, which the exporter stamps, the same in every
  graph of one set of weights, fp32 and int8) carry the same one: a folder holding graphs of two
  exports (a move into it cut short by a power cut, a file copied in from another export) is refused, naming
  two files and their ids. Files without one (exported before) are taken as before, beside stamped ones too
  (a warning names them); the painter and the skeleton prior are other networks, checked by their own
  metadata, not by this id;
* a ``<graph>.int8.onnx`` not quantized from the ``<graph>.onnx`` beside it (the fp32 file's sha256 it records,
  ``ghnerf.fp32_sha256``, is another; where it records none, it lacks that file's weights id or has another; where
  the fp32 file has none either, it is older by over ``onnx_file.STALE_INT8_AGE_S``) is not run: a folder
  exported before session 73 keeps the int8 file of a graph an export replaced. The fp32 file runs, with one warning
  naming both and the command that quantizes again; the painter's int8 file likewise (``NovelPainter.choose``);
* the resolution and variant match :class:`SessionConfig` when it pins them;
* the folder can be read by the user running this (:class:`ModelLoadError` naming it, not a bare
  PermissionError);
* at warm-up, and on every run after it, each output has the contract's shape, its symbolic sizes
  those of the inputs (:class:`ModelRunError`): the file's own output shapes leave some fixed sizes
  symbolic, so this is where a graph returning 24 joints shows; and at warm-up each output is finite (a graph
  whose weights hold NaN answers NaN to every input: :class:`ModelRunError` naming the graph and file).

Threads: the graphs run one after another on a 2-core CPU. Measured here (docs/runtime.md),
per-session pools whose workers do not spin are as fast as one global pool and far faster
than spinning pools (a spinning pool steals the cores from the next graph), and they keep no
process-wide onnxruntime state, so they are the default. ``thread_pool="global"`` installs
one global pool for the whole process (``set_global_thread_pool_sizes``), for the daemon.

onnxruntime, numpy only; never torch.
"""
from __future__ import annotations

import json
import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import onnxruntime as ort

from ghnerf_runtime.config import SessionConfig
from ghnerf_runtime.contract import (
    FP32_SHA256_KEY,
    GRAPH_NAMES,
    META_PREFIX,
    WEIGHTS_ID_KEY,
    ContractError,
    ModelContract,
    near_far_from_box,
    ray_grid,
    source_centers,
    source_projections,
    target_inputs,
    target_projections,
    weights_id_of,
)
from ghnerf_runtime.errors import ModelContractError, ModelError, ModelLoadError, ModelRunError
from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
from ghnerf_runtime.novel_painter import NovelPainter
from ghnerf_runtime.onnx_file import (
    ORT_LOG_SEVERITY,
    ensure_global_pool,
    load_failure,
    non_finite_output,
    onnx_metadata,
    ort_reason,
    stale_int8_reason,
    warn_stale_int8,
)
from ghnerf_runtime.skeleton_prior import FILE_NAME as PRIOR_FILE
from ghnerf_runtime.skeleton_prior import SkeletonPrior

log = logging.getLogger(__name__)

__all__ = ["AUTO_PRECISION", "GraphFile", "LaneRunner", "ModelSession", "MODEL_CARD", "check_graph_file",
           "resolve_model_dir", "usable_cores", "warmup_feeds"]

#: Optional model card next to the graphs.
MODEL_CARD = "model_card.json"
#: ``precision="auto"``: the faster file per graph on the 2-core AVX2 target (docs/model.md,
#: docs/runtime.md): int8 pays for the convolution-heavy encoder; the per-point heads of the
#: render/query graphs gain nothing (no VNNI) and their QDQ boundaries cost more on large
#: point counts; the volume graph is float in both files.
AUTO_PRECISION: Mapping[str, str] = {
    "encoder": "int8", "human": "int8", "volume": "fp32", "render_heat": "fp32", "render_rgb": "fp32",
    "render": "fp32", "query": "fp32",
}
_ONNX_FLOAT = "tensor(float)"


@dataclass(frozen=True)
class GraphFile:
    """One loaded graph: where it came from and what it is."""

    graph: str
    path: Path
    precision: str  # from the file's metadata
    load_ms: float
    weights_id: str | None = None  # ghnerf.weights_id; None in files exported before it


def resolve_model_dir(path: str | os.PathLike) -> Path:
    """The folder holding the graph files: ``path`` itself, else its ``ghnerf/`` subfolder, else its
    only subfolder holding ``*.onnx`` files (the shipped ``models/<variant>/`` layout). A path that is no
    folder comes back as it is, for the caller to say so.

    Raises:
        ModelLoadError: naming the folder, when it (or its ``ghnerf/`` subfolder) cannot be read: the service
            runs as its own user (``User=ghnerf``, ``ProtectHome=yes``), and a bare PermissionError from a
            ``stat`` left the daemon with a traceback instead of its "cannot load the model" exit.
    """
    folder = Path(path)
    try:
        if not folder.is_dir():
            return folder
        _check_readable(folder)
        if any(folder.glob("*.onnx")):
            return folder
        if (folder / "ghnerf").is_dir():
            _check_readable(folder / "ghnerf")
            if any((folder / "ghnerf").glob("*.onnx")):
                return folder / "ghnerf"
        subs = [d for d in sorted(folder.iterdir()) if d.is_dir() and any(d.glob("*.onnx"))]
    except ModelError:
        raise
    except OSError as e:  # a folder above it that this user may not enter, an I/O error
        where = f" ({e.filename})" if e.filename and str(e.filename) != str(folder) else ""
        why = " (the user this runs as may not enter a folder on its path)" if isinstance(e, PermissionError) else ""
        raise ModelLoadError(f"cannot read the model folder: {e.strerror or e}{where}{why}", path=str(folder)) from None
    return subs[0] if len(subs) == 1 else folder


def _check_readable(folder: Path) -> None:
    # Listing needs read permission and opening the files search (x) permission; glob() says neither, it
    # finds nothing in a folder it may not list.
    if not os.access(folder, os.R_OK | os.X_OK):
        raise ModelLoadError("cannot read the model folder: permission denied (the user this runs as needs read "
                             "and execute permission on it)", path=str(folder))


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity (a container's or systemd's ``CPUAffinity=``), else the
    machine's count."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):  # no sched_getaffinity (macOS, Windows)
        return os.cpu_count() or 1


def _what_is(path: Path) -> str:
    """What ``path``, which is no regular file, is instead (for an error naming it)."""
    if path.is_dir():
        return "a folder"
    if path.is_symlink() and not path.exists():
        return "a symbolic link that leads nowhere"
    return "no regular file (a device, a pipe or a socket)"


def _check_is_folder(folder: Path) -> None:
    """:class:`ModelLoadError` naming ``folder`` (``session.model_dir`` resolved) when it is no folder."""
    if not folder.is_dir():
        raise ModelLoadError("is not a folder (session.model_dir names the model folder, not a file)"
                             if folder.exists() else
                             # is_dir() and exists() are False for a link that leads nowhere, or in a loop
                             "is a symbolic link that leads to no folder (dangling, or a loop)"
                             if folder.is_symlink() else "model folder does not exist"
                             + ("" if folder.is_absolute() else f" (read from the current directory {Path.cwd()})"),
                             path=str(folder))


def _wanted_precision(graph: str, config: SessionConfig) -> tuple[str, bool]:
    """The precision ``config`` asks of ``graph``'s file, and whether only fp32 will do: fp32 asked for by name is
    fp32 or an error; int8 falls back to fp32 where a graph has no int8 file."""
    wanted = config.precision_overrides.get(
        graph, AUTO_PRECISION.get(graph, "fp32") if config.precision == "auto" else config.precision)
    return wanted, wanted == "fp32" and (graph in config.precision_overrides or config.precision == "fp32")


def _int8_by_name(graph: str, config: SessionConfig) -> bool:
    """Whether int8 was named for ``graph`` (session.precision or precision_overrides), not chosen by ``auto``."""
    return config.precision_overrides.get(graph, config.precision) == "int8"


def _file_name(graph: str, precision: str) -> str:
    return f"{graph}.int8.onnx" if precision == "int8" else f"{graph}.onnx"


def _session_options(config: SessionConfig) -> ort.SessionOptions:
    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = ORT_LOG_SEVERITY
    if config.thread_pool == "global":
        ensure_global_pool(config.threads)
        so.use_per_session_threads = False
    else:
        so.intra_op_num_threads = config.threads
        so.inter_op_num_threads = 1
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        if not config.allow_spinning:
            so.add_session_config_entry("session.intra_op.allow_spinning", "0")
            so.add_session_config_entry("session.inter_op.allow_spinning", "0")
    return so


def _open(path: Path, config: SessionConfig) -> ort.InferenceSession:
    if not path.is_file():
        raise ModelLoadError("no such model file", path=str(path))
    try:
        return ort.InferenceSession(str(path), _session_options(config), providers=["CPUExecutionProvider"])
    except ModelError:
        raise
    except Exception as e:  # onnxruntime raises its own (pybind) exception types
        raise load_failure(e, path, "graph file") from e


def _contract_of(sess: ort.InferenceSession, path: Path) -> tuple[ModelContract, str, str]:
    props = dict(sess.get_modelmeta().custom_metadata_map)
    if not any(k.startswith(META_PREFIX) for k in props):
        raise ModelContractError("the file has no ghnerf.* metadata: not a GHNeRF export (or exported before "
                                 "the contract existed)", path=str(path), key=META_PREFIX + "contract_version")
    try:
        contract = ModelContract.from_metadata(props)
        graph = ModelContract.graph_of(props)
    except ContractError as e:
        raise ModelContractError(str(e).split(": ", 1)[-1] if e.key else str(e), path=str(path), key=e.key) from e
    precision = props.get(META_PREFIX + "precision", "fp32")
    if precision not in ("fp32", "int8"):  # what session.precision chooses between
        raise ModelContractError(f"precision must be 'fp32' or 'int8', got {precision!r}", path=str(path),
                                 key=META_PREFIX + "precision")
    return contract, graph, precision


def _weights_of(sess: ort.InferenceSession, path: Path) -> str | None:
    """The file's weights id (``ghnerf.weights_id``), None in a file exported before there was one."""
    try:
        return weights_id_of(dict(sess.get_modelmeta().custom_metadata_map))
    except ContractError as e:
        raise ModelContractError(str(e).split(": ", 1)[-1], path=str(path), key=e.key) from e


def _check_io(sess: ort.InferenceSession, contract: ModelContract, graph: str, path: Path) -> None:
    inputs = {i.name: i.shape for i in sess.get_inputs()}
    outputs = {o.name: o.shape for o in sess.get_outputs()}
    try:
        contract.check_io(graph, inputs, outputs)
    except ContractError as e:
        raise ModelContractError(str(e).split(": ", 1)[-1], path=str(path), key=e.key) from e
    for arg in list(sess.get_inputs()) + list(sess.get_outputs()):
        if arg.type != _ONNX_FLOAT:
            raise ModelContractError(f"tensor type {arg.type}, the contract says float32", path=str(path),
                                     key=arg.name)


def check_graph_file(path: str | os.PathLike, graph: str, precision: str | None = None) -> ModelContract:
    """What :meth:`ModelSession.load` checks of one graph file, on its own: onnxruntime loads it, its metadata
    parse into a contract, it holds ``graph`` (of ``precision``, when given), and its inputs and outputs match
    the contract. The exporter and the quantizer run it on each file they write (and the quantizer on the fp32
    file it reads), so a file the runtime would refuse is refused where it is made, naming the file.

    Raises:
        ModelLoadError: a missing, truncated or corrupt file.
        ModelContractError: naming the file and the metadata key or tensor that is wrong.
    """
    path = Path(path)
    sess = _open(path, SessionConfig(model_dir=str(path.parent), threads=1, warmup=False))
    contract, file_graph, file_precision = _contract_of(sess, path)
    if file_graph != graph:
        raise ModelContractError(f"holds graph {file_graph!r}, expected {graph!r}", path=str(path),
                                 key=META_PREFIX + "graph")
    if precision is not None and file_precision != precision:
        raise ModelContractError(f"holds {file_precision} weights, expected {precision}", path=str(path),
                                 key=META_PREFIX + "precision")
    _check_io(sess, contract, graph, path)
    _weights_of(sess, path)
    return contract


class ModelSession:
    """The onnxruntime sessions of one model's graphs, checked against the model contract.

    Build with :meth:`load`; run a graph with :meth:`run`. Instances are not thread-safe for
    concurrent :meth:`run` calls on one graph (onnxruntime is, but the run counters are
    kept for instrumentation, not locked).

    Attributes:
        contract: the model contract (identical in every graph file).
        files: graph -> :class:`GraphFile` actually loaded.
        card: the parsed ``model_card.json`` (``{}`` when absent).
        skeleton_prior: the folder's :class:`~ghnerf_runtime.skeleton_prior.SkeletonPrior` when
            :meth:`load` was asked for it and the folder has one, else None.
        run_counts: graph -> number of :meth:`run` calls (instrumentation).
        warmup_ms: graph -> duration of the warm-up run (empty when warm-up is off); ``"skeleton_prior"`` the
            prior's (:meth:`~ghnerf_runtime.skeleton_prior.SkeletonPrior.warm_up`).
    """

    def __init__(self, sessions: Mapping[str, ort.InferenceSession], contract: ModelContract,
                 files: Mapping[str, GraphFile], card: Mapping | None = None) -> None:
        self._sessions = dict(sessions)
        self.contract = contract
        self.files = dict(files)
        self.card = dict(card or {})
        self.run_counts: dict[str, int] = {g: 0 for g in self._sessions}
        self.warmup_ms: dict[str, float] = {}
        self.skeleton_prior = None
        self.novel_painter = None
        self._output_names = {g: list(contract.graph(g).output_names) for g in self._sessions}
        self._input_names = {g: list(contract.graph(g).input_names) for g in self._sessions}
        # (input, axis, symbol) binding each symbolic size, and the outputs' shapes: _check_outputs' tables
        self._symbols = {g: [(t.name, axis, d) for t in contract.graph(g).inputs for axis, d in enumerate(t.shape)
                             if isinstance(d, str)] for g in self._sessions}
        self._output_shapes = {g: [(t.name, t.shape) for t in contract.graph(g).outputs] for g in self._sessions}
        self._config: SessionConfig | None = None  # set by load(); lanes need it
        self._lanes: dict[str, ort.InferenceSession] = {}
        self._lane_worker: ThreadPoolExecutor | None = None

    # ------------------------------------------------------------------ load
    @classmethod
    def load(cls, config: SessionConfig | str | os.PathLike,
             graphs: Sequence[str] = ("encoder", "volume", "render_heat"),
             skeleton_prior: bool = False, novel_painter: bool = False) -> "ModelSession":
        """Load, check and warm up ``graphs`` of the model in ``config.model_dir``.

        Args:
            config: a :class:`SessionConfig`, or just the model folder (defaults otherwise).
            graphs: which graphs to load (``EstimatorConfig.required_graphs()``).
            skeleton_prior: also load the folder's ``skeleton_prior.onnx`` when it has one.
            novel_painter: also load the folder's ``novel_painter.onnx`` when it has one.

        Raises:
            ModelLoadError: a folder or file is missing, unreadable or not valid ONNX.
            ModelContractError: a file's contract is missing, malformed, of another version,
                of another model than the other files, or does not match its graph's I/O or
                the configured resolution/variant.
        """
        if not isinstance(config, SessionConfig):
            config = SessionConfig(model_dir=str(config))
        folder = resolve_model_dir(config.model_dir)
        _check_is_folder(folder)
        unknown = [g for g in graphs if g not in GRAPH_NAMES]
        if unknown:
            raise ModelError(f"unknown graph(s) {unknown}; graphs are {list(GRAPH_NAMES)}", path=str(folder))
        cores = usable_cores()
        if config.threads > cores:
            # Not an error: the config may be written for another machine. Said, as onnxruntime takes any count
            # and its threads then only share the cores there are.
            log.warning("session.threads is %d, more than the %d core(s) this process may run on: onnxruntime's "
                        "threads only share those (docs/runtime.md, \"Threads\")", config.threads, cores)
        if not graphs:  # the contract comes from the graph files: none loaded, no model
            raise ModelError(f"no graphs to load; graphs are {list(GRAPH_NAMES)}", path=str(folder))

        sessions: dict[str, ort.InferenceSession] = {}
        files: dict[str, GraphFile] = {}
        contract: ModelContract | None = None
        first: Path | None = None
        stamped: tuple[Path, str] | None = None  # the first file loaded that has a weights id, and the id
        by_meta: dict[tuple[str, str], Path] = {}
        fell_back: list[str] = []  # graphs asked for int8 by name that run an fp32 file
        stale: list[tuple[Path, Path, str]] = []  # (int8, fp32, why): int8 files not quantized from the fp32 beside
        for graph in dict.fromkeys(graphs):
            only_fp32 = _wanted_precision(graph, config)[1]
            path = cls._locate(folder, graph, config, by_meta)
            if (stale_twin := cls._stale_int8(folder, graph, path)) is not None:
                stale.append(stale_twin)
                path = stale_twin[1]
            t0 = time.perf_counter()
            sess = _open(path, config)
            load_ms = 1e3 * (time.perf_counter() - t0)
            file_contract, file_graph, precision = _contract_of(sess, path)
            if file_graph != graph:
                raise ModelContractError(f"holds graph {file_graph!r}, loaded as {graph!r}", path=str(path),
                                         key=META_PREFIX + "graph")
            if only_fp32 and precision != "fp32":
                raise ModelContractError(f"holds {precision} weights, and fp32 was asked for graph {graph!r} "
                                         f"(session.precision / precision_overrides)", path=str(path),
                                         key=META_PREFIX + "precision")
            _check_io(sess, file_contract, graph, path)
            if contract is None:
                contract, first = file_contract, path
                cls._check_expected(contract, config, path)
            elif not contract.same_model(file_contract):
                diff = sorted(k for k, v in contract.to_metadata().items()
                              if file_contract.to_metadata().get(k) != v)
                raise ModelContractError(f"its contract differs from {first.name}'s in {diff}: the graph files "
                                         "come from different models", path=str(path), key=diff[0] if diff else None)
            # the same contract, other weights: graphs of two exports of one model, which would run as one and
            # give wrong but plausible joints
            weights = _weights_of(sess, path)
            if weights is not None and stamped is None:
                stamped = (path, weights)
            elif weights is not None and stamped is not None and weights != stamped[1]:
                raise ModelContractError(
                    f"{path.name} has weights id {weights[:16]}... and {stamped[0].name} {stamped[1][:16]}...: the "
                    "graph files come from two different exports (a move into the folder cut short, by a power cut "
                    "say, or a file copied in from another export); export the model again into this folder "
                    "(python -m training.export --out, or make model)", path=str(path), key=WEIGHTS_ID_KEY)
            sessions[graph] = sess
            files[graph] = GraphFile(graph, path, precision, load_ms, weights)
            log.info("loaded %s (%s, %.0f ms)", path, precision, load_ms)
            if (_int8_by_name(graph, config) and precision != "int8" and path.name != _file_name(graph, "int8")
                    and stale_twin is None):  # (said below, with why)
                fell_back.append(path.name)
        warn_stale_int8(folder, stale, f"python -m training.export --checkpoint CHECKPOINT.pt --out {folder} --int8")
        if fell_back:
            # documented (int8 falls back to fp32), but a user who named int8 (ghnerf-run --precision int8) and
            # timed the run took it for int8's figures: said once, naming the files
            log.warning("%s: int8 was asked for (session.precision / precision_overrides), and the folder has no "
                        "int8 file for this graph: running the fp32 %s", folder, ", ".join(fell_back))
        assert contract is not None
        unstamped = [f.path.name for f in files.values() if f.weights_id is None]
        if stamped is not None and unstamped:  # taken, as a folder of older files is: nothing to compare them with
            log.warning("%s: %s carry no weights id (exported before there were ids), so they cannot be checked to "
                        "be of the same export as %s; export the model again to check them", folder,
                        ", ".join(unstamped), stamped[0].name)
        session = cls(sessions, contract, files, cls._read_card(folder))
        session._config = config
        if skeleton_prior and (folder / PRIOR_FILE).is_file():
            session.skeleton_prior = SkeletonPrior.load(folder / PRIOR_FILE, threads=1)  # one small MLP row: no pool
            session.skeleton_prior.check_encoder(folder)
        painter_file = NovelPainter.choose(folder, config.precision) if novel_painter else None
        if painter_file is not None:
            session.novel_painter = NovelPainter.load(painter_file, threads=config.threads)
        if config.warmup:
            session.warm_up()
        return session

    @classmethod
    def has_skeleton_prior(cls, config: SessionConfig | str | os.PathLike) -> bool:
        """Whether the model folder has a skeleton prior file (:meth:`load` with ``skeleton_prior`` loads it)."""
        if not isinstance(config, SessionConfig):
            config = SessionConfig(model_dir=str(config))
        return (resolve_model_dir(config.model_dir) / PRIOR_FILE).is_file()

    @classmethod
    def has_graph_file(cls, config: SessionConfig | str | os.PathLike, graph: str) -> bool:
        """Whether the model folder has a file for ``graph`` under its usual names (``<graph>.onnx``,
        ``<graph>.int8.onnx``): how the caller learns, before loading, that an optional graph exists."""
        if not isinstance(config, SessionConfig):
            config = SessionConfig(model_dir=str(config))
        folder = resolve_model_dir(config.model_dir)
        return any(cls._find(folder, graph, p) is not None for p in ("fp32", "int8"))

    @classmethod
    def check_files(cls, config: SessionConfig, graphs: Sequence[str]) -> Path:
        """What :meth:`load` checks before it opens a graph: the model folder is a folder, and holds a file for each
        of ``graphs`` (by its usual names; by ``ghnerf.graph`` metadata, which opens the folder's files, only for a
        graph without one). Nothing else is loaded or checked: for ``ghnerf-run --validate-config``, which names a
        missing folder, a file given as one, or a graph the settings run that the folder lacks, without loading
        the model (docs/runtime.md, "The model folder; switching models": it checks the settings, not the files).

        :returns: the resolved folder (:func:`resolve_model_dir`).
        :raises ModelLoadError: naming the folder or file, in :meth:`load`'s words.
        """
        folder = resolve_model_dir(config.model_dir)
        _check_is_folder(folder)
        by_meta: dict[tuple[str, str], Path] = {}
        for graph in dict.fromkeys(graphs):
            cls._locate(folder, graph, config, by_meta)
        return folder

    @classmethod
    def _locate(cls, folder: Path, graph: str, config: SessionConfig,
                by_meta: dict[tuple[str, str], Path]) -> Path:
        """The file :meth:`load` opens for ``graph``: by name, else by metadata (``by_meta``, filled on first need
        by :meth:`_scan` and kept across graphs).

        :raises ModelLoadError: naming the folder (no file) or what lies under the graph's name instead.
        """
        wanted, only_fp32 = _wanted_precision(graph, config)
        path = cls._find(folder, graph, wanted)
        if path is None:
            # empty means not scanned yet: an empty scan finds no file for this graph, which raises below, so a
            # folder is never scanned twice; the scan's answer is the folder's and config's, fixed for one load
            if not by_meta:
                by_meta.update(cls._scan(folder, config))
            path = by_meta.get((graph, wanted)) or by_meta.get((graph, "fp32")) or (
                None if only_fp32 else by_meta.get((graph, "int8")))
        if path is not None:
            return path
        names = list(dict.fromkeys((_file_name(graph, wanted), _file_name(graph, "fp32"))))
        # a folder (or a link to nowhere) under the graph's own name: "no file for graph" sent the user
        # looking for a file that ls shows
        odd = next((folder / n for n in names if (folder / n).exists() or (folder / n).is_symlink()), None)
        if odd is not None:
            raise ModelLoadError(f"is not a graph file but {_what_is(odd)}: graph {graph!r} cannot be "
                                 "loaded from it", path=str(odd))
        raise ModelLoadError(f"no file for graph {graph!r} (looked for {', '.join(names)} and "
                             "ghnerf.graph metadata)", path=str(folder))

    @staticmethod
    def _stale_int8(folder: Path, graph: str, path: Path) -> tuple[Path, Path, str] | None:
        """``(path, fp32 file, why)`` where ``path`` is ``graph``'s int8 file by name and was not quantized from the
        fp32 file beside it (:func:`~ghnerf_runtime.onnx_file.stale_int8_reason`): the sha256 of the fp32 file the
        quantizer recorded in the int8 one (``ghnerf.fp32_sha256``) decides where it has one; else the fp32 file's
        weights id (the quantizer stamps it in the int8 file), their times where it has none. A folder exported
        before session 73 keeps the int8 files of graphs an export replaced, and ``auto`` took them. Judged from the
        files' metadata before either is opened: onnxruntime loads only the file that runs."""
        fp32 = folder / _file_name(graph, "fp32")
        if path.name != _file_name(graph, "int8") or not fp32.is_file():
            return None
        try:
            fp32_weights = onnx_metadata(fp32, "fp32 graph").get(WEIGHTS_ID_KEY)
            int8_meta = onnx_metadata(path, "graph")
        except ModelLoadError:  # the int8 file is loaded, as before (and names its own error)
            return None
        # an fp32 file with an id and an int8 one without: quantized before ids, so from another fp32 file (the
        # quantizer copies the id since ids exist); an int8 file with one beside an fp32 file without: the times say
        differs = None if fp32_weights is None else [] if fp32_weights == int8_meta.get(WEIGHTS_ID_KEY) else [
            "weights id"]
        why = stale_int8_reason(path, fp32, differs, int8_meta.get(FP32_SHA256_KEY))
        return None if why is None else (path, fp32, why)

    @staticmethod
    def _find(folder: Path, graph: str, precision: str) -> Path | None:
        for name in (_file_name(graph, precision), _file_name(graph, "fp32")):
            if (folder / name).is_file():
                return folder / name
        return None

    @staticmethod
    def _scan(folder: Path, config: SessionConfig) -> dict[tuple[str, str], Path]:
        """(graph, precision) -> file, for files named otherwise; unreadable files are skipped here."""
        found: dict[tuple[str, str], Path] = {}
        for path in sorted(folder.glob("*.onnx")):
            try:
                sess = _open(path, config)
                _, graph, precision = _contract_of(sess, path)
            except ModelError:
                continue
            found.setdefault((graph, precision), path)
        return found

    @staticmethod
    def _check_expected(contract: ModelContract, config: SessionConfig, path: Path) -> None:
        res = config.expected_resolution
        if res is not None and (contract.height, contract.width) != (res, res):
            raise ModelContractError(f"model resolution is {contract.width}x{contract.height}, the runtime is "
                                     f"configured for {res}x{res} (session.expected_resolution)", path=str(path),
                                     key=META_PREFIX + "resolution")
        if config.expected_variant is not None and contract.variant != config.expected_variant:
            raise ModelContractError(f"model variant is {contract.variant!r}, configured "
                                     f"{config.expected_variant!r}", path=str(path), key=META_PREFIX + "variant")

    @staticmethod
    def _read_card(folder: Path) -> dict:
        path = folder / MODEL_CARD
        if not path.is_file():
            path = folder.parent / MODEL_CARD
        if not path.is_file():
            return {}
        try:
            card = json.loads(path.read_text(encoding="utf-8-sig"))
        except (OSError, ValueError, RecursionError) as e:  # ValueError: bad JSON or UTF-8, 5000-digit integers
            log.warning("%s: unreadable model card ignored (%s)", path, e)
            return {}
        return card if isinstance(card, dict) else {"card": card}

    # ------------------------------------------------------------------ run
    @property
    def graphs(self) -> tuple[str, ...]:
        return tuple(self._sessions)

    @property
    def weights_id(self) -> str | None:
        """The weights id the loaded graphs share (:meth:`load` checks that they do), None when none has one."""
        return next((f.weights_id for f in self.files.values() if f.weights_id is not None), None)

    def has(self, graph: str) -> bool:
        return graph in self._sessions

    def precision(self, graph: str) -> str:
        return self.files[graph].precision

    def run(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Run one graph. ``feeds`` may hold more arrays than the graph takes; only its inputs are passed.

        Returns:
            output name -> array.

        Raises:
            ModelError: the graph was not loaded, or an input is missing.
            ModelRunError: onnxruntime failed (message names the graph and file).
        """
        sess = self._sessions.get(graph)
        if sess is None:
            raise ModelError(f"graph {graph!r} is not loaded (loaded: {list(self._sessions)})")
        return self._run_in(sess, graph, feeds)

    def _run_in(self, sess: ort.InferenceSession, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``graph`` run in ``sess`` (its session or its lane), counted; a failure names the graph and file."""
        inputs = self._inputs(graph, feeds)
        self.run_counts[graph] += 1
        try:
            out = sess.run(self._output_names[graph], inputs)
        except Exception as e:  # onnxruntime's pybind exceptions
            raise self._failed(graph, e) from e
        outputs = dict(zip(self._output_names[graph], out))
        self._check_outputs(graph, inputs, outputs)
        return outputs

    def _check_outputs(self, graph: str, inputs: Mapping[str, np.ndarray], outputs: Mapping[str, np.ndarray]) -> None:
        """Each output's shape is the contract's, its symbolic sizes (``B``, ``R``, ``N``) those of the inputs.

        The file's own output shapes are often symbolic where the contract fixes a size (the fp32 heatmaps'
        joint axis reads ``Transposeheatmaps_dim_2``), so the load cannot see a graph that returns 24 joints,
        or one target for two: the estimator then sent 24 "BODY_25" joints on the wire, or failed with an
        IndexError that stopped the daemon. Run at warm-up, this refuses such a file at load.
        """
        sizes = {d: np.shape(inputs[name])[axis] for name, axis, d in self._symbols[graph]}  # ranks: checked by ort
        for name, shape in self._output_shapes[graph]:
            want = tuple([sizes.get(d, d) for d in shape]) if sizes else shape
            got = np.shape(outputs[name])
            if got != want and (len(got) != len(want)  # (a symbol no input binds matches any size)
                                or any(w != n for w, n in zip(want, got) if not isinstance(w, str))):
                raise ModelRunError(f"graph {graph!r} returned {name!r} of shape {list(got)}, the contract says "
                                    f"{list(shape)} ({list(want)} for these inputs)", path=str(self.files[graph].path))

    def _inputs(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The graph's own inputs out of ``feeds`` (which may hold more)."""
        try:
            return {n: feeds[n] for n in self._input_names[graph]}
        except KeyError as e:
            raise ModelError(f"graph {graph!r} needs input {e.args[0]!r}") from None

    def _failed(self, graph: str, e: Exception) -> ModelRunError:
        return ModelRunError(f"graph {graph!r} failed: {type(e).__name__}: {ort_reason(e, 300)}",
                             path=str(self.files[graph].path))

    # ------------------------------------------------------------------ lanes
    def open_lane(self, graph: str) -> bool:
        """Prepare :meth:`run_both` and :meth:`run_on_lane` for ``graph``: a second session of its file with one
        intra-op thread, run once. Only where the graphs have a pool of their own of two or more threads (``thread_pool:
        "per_session"``, ``threads >= 2``): two one-thread runs side by side then take the cores the one run
        shared (a 2-thread ``human`` run scales 1.5x over one thread, so two runs side by side finish sooner
        than two in turn). Returns whether :meth:`run_both` runs side by side."""
        cfg = self._config
        if graph in self._lanes:
            return True
        if cfg is None or cfg.thread_pool != "per_session" or cfg.threads < 2 or graph not in self._sessions:
            return False
        lane = _open(self.files[graph].path, replace(cfg, threads=1))
        lane.run(self._output_names[graph], self._inputs(graph, self._lane_warmup_feeds(graph)))  # the first is slow
        self._lanes[graph] = lane
        if self._lane_worker is None:
            self._lane_worker = ThreadPoolExecutor(1, thread_name_prefix="ghnerf-lane")
        return True

    def _lane_warmup_feeds(self, graph: str) -> dict[str, np.ndarray]:
        """Inputs for a lane's first run at the estimator's shapes: the novel view's graphs (one target, every
        ray) read the encoder's and the volume's outputs, run here on the loaded sessions (not counted)."""
        if graph not in ("volume", "render_rgb", "render"):
            return warmup_feeds(self.contract)
        feeds = warmup_feeds(self.contract, targets=1, ray_stride=1)
        for g in ("encoder", "volume") if graph != "volume" else ("encoder",):
            names = self._output_names[g]
            feeds.update(zip(names, self._sessions[g].run(names, self._inputs(g, feeds))))
        return feeds

    def run_on_lane(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """:meth:`run` on ``graph``'s one-thread lane (:meth:`open_lane`) when it has one, else as :meth:`run`: for
        a run beside another thread's, so that the two take one core each rather than four threads two cores
        (a 2-thread run waits for its slower thread, and one descheduled stalls it). The same numbers."""
        lane = self._lanes.get(graph)
        if lane is None:
            return self.run(graph, feeds)
        return self._run_in(lane, graph, feeds)

    def on_lanes(self) -> "LaneRunner":
        """This session with :meth:`run` on the lanes (:meth:`run_on_lane`): what a worker thread is handed."""
        return LaneRunner(self)

    def run_both(self, graph: str, first: Mapping[str, np.ndarray],
                 second: Mapping[str, np.ndarray]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """:meth:`run` of ``graph`` on two sets of feeds: side by side on its lane (:meth:`open_lane`), one
        thread each, else one after the other. The answers are the same either way (the int8 kernels give the
        same numbers on one thread or two)."""
        lane = self._lanes.get(graph)
        if lane is None:
            return self.run(graph, first), self.run(graph, second)
        inputs = [self._inputs(graph, feeds) for feeds in (first, second)]
        names = self._output_names[graph]
        self.run_counts[graph] += 2
        try:
            later = self._lane_worker.submit(lane.run, names, inputs[1])
            try:
                out = lane.run(names, inputs[0])
            finally:
                out2 = later.result()  # never leave a run behind, whatever the first did
        except Exception as e:  # onnxruntime's pybind exceptions
            raise self._failed(graph, e) from e
        answers = dict(zip(names, out)), dict(zip(names, out2))
        for feeds, outputs in zip(inputs, answers):
            self._check_outputs(graph, feeds, outputs)
        return answers

    def warm_up(self) -> dict[str, float]:
        """Run every loaded graph once at the estimator's shapes, and the skeleton prior where loaded
        (:meth:`~ghnerf_runtime.skeleton_prior.SkeletonPrior.warm_up`), so the first frame is not slow; returns
        :attr:`warmup_ms`'s copy."""
        feeds = warmup_feeds(self.contract)
        order = [g for g in ("human", "encoder", "volume", "render_heat", "query") if g in self._sessions]
        for graph in order:
            t0 = time.perf_counter()
            feeds.update(self._warm_run(graph, feeds))
            self.warmup_ms[graph] = 1e3 * (time.perf_counter() - t0)
        novel = [g for g in ("render_rgb", "render") if g in self._sessions]
        if novel:
            one = warmup_feeds(self.contract, targets=1, ray_stride=1)
            one.update({k: feeds[k] for k in ("feat_s1", "feat_s2", "feat_s4", "human_feat") if k in feeds})
            one.update(self._warm_run("volume", one))
            for graph in novel:
                t0 = time.perf_counter()
                self._warm_run(graph, one)
                self.warmup_ms[graph] = 1e3 * (time.perf_counter() - t0)
        if self.skeleton_prior is not None:
            self.warmup_ms["skeleton_prior"] = self.skeleton_prior.warm_up()
        for graph in self.run_counts:  # warm-up runs are not counted as work
            self.run_counts[graph] = 0
        return dict(self.warmup_ms)

    def _warm_run(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """:meth:`run` at warm-up, refusing NaN or infinite outputs: a graph whose weights hold them (a diverged
        run's, exported) answers NaN to every input, and ran without a word, finding no one, frame after frame.
        Only here: on a real frame a graph's output may be what the estimator treats as missing."""
        outputs = self.run(graph, feeds)
        if (non_finite := non_finite_output(outputs.items())) is not None:
            name, bad, size = non_finite
            raise ModelRunError(f"graph {graph!r} returned {bad} NaN or infinite value(s) of {size} in {name!r} at "
                                "warm-up: its weights hold NaN or infinite values (a run that diverged?); export a "
                                "checkpoint from before it", path=str(self.files[graph].path))
        return outputs

    def reset_counts(self) -> None:
        for graph in self.run_counts:
            self.run_counts[graph] = 0

    def describe(self) -> dict:
        """A JSON-ready summary: contract basics, files and their precision."""
        c = self.contract
        return {"resolution": f"{c.width}x{c.height}", "variant": c.variant, "model_version": c.model_version,
                "contract_version": c.version, "weights_id": self.weights_id,
                "frame_padding": c.frame_padding,  # what its training crops showed past the frame
                "files": {g: {"path": str(f.path), "precision": f.precision} for g, f in self.files.items()},
                "card": bool(self.card)}


class LaneRunner:
    """A :class:`ModelSession` whose :meth:`run` goes to the graphs' one-thread lanes where they have one
    (:meth:`ModelSession.run_on_lane`); ``contract`` and :meth:`has` as the session's."""

    def __init__(self, session: ModelSession) -> None:
        self.session = session
        self.contract = session.contract

    def has(self, graph: str) -> bool:
        return self.session.has(graph)

    def run(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return self.session.run_on_lane(graph, feeds)


def warmup_feeds(contract: ModelContract, targets: int = 2, ray_stride: int | None = None,
                 points: int = 512) -> dict[str, np.ndarray]:
    """Plausible inputs for every graph: grey images, two cameras 1 m apart looking at a box 3 m away.

    ``targets`` 2 uses the sources as targets (the keypoint path); 1 uses one camera between
    them (the novel view). ``ray_stride`` defaults to the heatmap stride.
    """
    H, W = contract.height, contract.width
    K = intrinsics_from_fov(W, H, 25.0)
    box = np.array([[-0.4, -1.9, 2.7], [0.4, 0.0, 3.3]])
    centre = box.mean(axis=0)
    src = [Camera(n, W, H, K, np.zeros(5), *look_at((x, -1.2, 0.0), centre)) for n, x in (("a", -0.5), ("b", 0.5))]
    tgts = src if targets == 2 else [Camera("n", W, H, K, np.zeros(5), *look_at((0.0, -1.2, 0.0), centre))]
    stride = contract.heatmap_stride if ray_stride is None else ray_stride
    rays = ray_grid(H, W, stride)
    rng = np.random.default_rng(0)
    feeds = {
        "images": rng.uniform(0.3, 0.7, (contract.num_sources, 3, H, W)).astype(np.float32),
        "src_P": source_projections(src, H, W),
        "src_centers": source_centers(src),
        **target_inputs(tgts, H, W),
        "tgt_P": target_projections(tgts, H, W),
        "near_far": np.stack([near_far_from_box(c, box) for c in tgts]),
        "ray_uv": np.ascontiguousarray(np.broadcast_to(rays, (len(tgts),) + rays.shape)),
        "points": rng.uniform(box[0], box[1], (len(tgts), points, 3)).astype(np.float32),
    }
    return feeds
