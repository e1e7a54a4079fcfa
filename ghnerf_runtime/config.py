"""Configuration of the runtime: one frozen dataclass per component, nested under one root.

Every dataclass validates itself on construction (``__post_init__``); :func:`config_from_dict`
builds the tree from plain data (a JSON file) and rejects unknown keys by their dotted path,
so a typo in a device config fails at load with ``ConfigError("joints3d.metod: unknown key
...")`` rather than being ignored. Nothing here reads the environment or a global file: the
caller passes one explicit path (:func:`load_config`).

Tree (defaults in the classes)::

    EstimatorConfig
      session      SessionConfig        model folder, precision per graph, threads, warm-up
      roi          RoiConfig            crop window: working volume or tracked joints
      tracking     TrackingConfig       when to keep / drop the track, subject box margins
      frame_check  FrameCheckConfig     black / saturated / noise frames
      rays         RaysConfig           which heatmap rays are rendered
      decoder      KeypointDecoderConfig  (ghnerf_runtime.keypoints) 2D peak decoding
      joints3d     Joints3DConfig       3D method and its parameters
      novel_view   NovelViewConfig      novel-view rendering (off by default)
      smoothing    SmoothingConfig      One Euro filtering of the reported 3D joints (on; needs capture times)
"""
from __future__ import annotations

import dataclasses
import numbers
import os
import typing
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from ghnerf_runtime.config_paths import impossible_path, paths_from_file
from ghnerf_runtime.contract import GRAPH_NAMES, MAX_NEAR_FAR_MARGIN_M
from ghnerf_runtime.errors import ConfigError
from ghnerf_runtime.json_keys import JsonTextError, first_repeat, loads_remembering
from ghnerf_runtime.keypoints import KeypointConfigError, KeypointDecoderConfig
from ghnerf_runtime.plain_values import is_finite_number, is_true_false, plain_scalar
from ghnerf_runtime.preprocess import EDGE_CROPS, PAD_FILLS

__all__ = [
    "PRECISIONS", "THREE_D_METHODS", "SKELETON_PRIOR_MODES", "NOVEL_SILHOUETTE_STRIDES", "NOVEL_PATHS",
    "MIN_CUTOFF_HZ", "HEATMAP_SOURCES", "BEST_METHOD", "PRESENCE_MIN_CONFIDENCE", "SessionConfig",
    "RoiConfig", "TrackingConfig", "FrameCheckConfig", "RaysConfig", "HeatmapsConfig", "Joints3DConfig",
    "PresenceConfig", "NovelViewConfig", "SmoothingConfig", "EstimatorConfig", "config_from_dict", "config_to_dict",
    "load_config", "read_json_file", "PATH_KEYS",
]

#: The keys holding file-system paths; a relative one written in a config file is read from the file's folder.
PATH_KEYS: tuple[tuple[str, ...], ...] = (("session", "model_dir"),)

#: Precision choices of :class:`SessionConfig`.
PRECISIONS = ("fp32", "int8", "auto")
#: 3D joint methods of :class:`Joints3DConfig`.
THREE_D_METHODS = ("triangulate", "volumetric", "depth_centroid")
#: :attr:`Joints3DConfig.skeleton_prior` choices.
SKELETON_PRIOR_MODES = ("auto", "on", "off")
#: :attr:`Joints3DConfig.pick_subject` choices: which of two people seen without a track becomes the subject.
PICK_SUBJECT_RULES = ("centre_line", "nearest", "none")
#: :attr:`NovelViewConfig.silhouette_stride` choices: the powers of two up to 16, which divide the model
#: resolutions in use (64, 128); :class:`~ghnerf_runtime.estimator.Estimator` checks them against its model's.
NOVEL_SILHOUETTE_STRIDES = (0, 1, 2, 4, 8, 16)
#: :attr:`NovelViewConfig.path` choices: how a camera between the rig's two moves from one to the other.
NOVEL_PATHS = ("line", "orbit", "auto")
#: The lowest :class:`SmoothingConfig` cutoff, Hz: a time constant of 159 s, far steadier than any use wants.
MIN_CUTOFF_HZ = 1e-3


# ------------------------------------------------------------------ checks
def _fail(cls: type, name: str, why: str, value: Any) -> None:
    raise ConfigError(f"{why}, got {value!r}", key=f"{cls.__name__}.{name}")


def _keep_plain(obj: Any, name: str, value: Any) -> None:
    """Store a checked value as the Python type it stands for: a NumPy scalar (np.float32, np.int64, np.bool_) kept as
    given made :func:`config_to_dict`, documented JSON-ready, fail in ``json.dumps``."""
    object.__setattr__(obj, name, plain_scalar(value))


def _number(obj: Any, name: str, lo: float, hi: float, *, lo_open: bool = False) -> None:
    value = getattr(obj, name)
    ok = is_finite_number(value) and (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        _fail(type(obj), name, f"must be a number in {'(' if lo_open else '['}{lo}, {hi}]", value)
    _keep_plain(obj, name, value)


def _integer(obj: Any, name: str, lo: int, hi: int) -> None:
    value = getattr(obj, name)
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool) and lo <= value <= hi):
        _fail(type(obj), name, f"must be an integer in [{lo}, {hi}]", value)
    _keep_plain(obj, name, value)


def _boolean(obj: Any, name: str) -> None:
    value = getattr(obj, name)
    if not is_true_false(value):  # numpy's True too (a comparison's result); 1 and "yes" are not
        _fail(type(obj), name, "must be true or false", value)
    _keep_plain(obj, name, value)


def _choice(obj: Any, name: str, choices: tuple) -> None:
    value = getattr(obj, name)
    if value not in choices:
        _fail(type(obj), name, f"must be one of {list(choices)}", value)
    _keep_plain(obj, name, value)


# ------------------------------------------------------------------ components
@dataclass(frozen=True)
class SessionConfig:
    """How the model is loaded and run (:class:`ghnerf_runtime.session.ModelSession`).

    Attributes:
        model_dir: folder holding ``<graph>.onnx`` (fp32) and ``<graph>.int8.onnx`` files, as
            ``python -m training.export`` writes them (and optionally ``model_card.json``). A relative
            path written in a config file is read from the file's folder (:func:`load_config`); the
            default, and a path given in code, from the current directory.
            Switching to another model is only this path.
        precision: ``"fp32"``: the fp32 file of every graph; ``"int8"``: the int8 file of every
            graph that has one; ``"auto"``: the faster file per graph as measured on the
            2-core target (:data:`ghnerf_runtime.session.AUTO_PRECISION`). The novel view's painter
            (``novel_painter.onnx``) is int8 under ``"auto"`` and ``"int8"`` where the folder has its
            int8 file.
        precision_overrides: graph -> ``"fp32"`` / ``"int8"``, applied after ``precision``.
        threads: intra-op threads (the device has 2 cores).
        thread_pool: ``"per_session"``: each graph session owns a pool of ``threads`` whose
            workers do not spin (measured as fast as a global pool here, and it keeps no
            process-wide state); ``"global"``: one onnxruntime pool for every session of the
            process (``set_global_thread_pool_sizes``; once set, every onnxruntime session of
            the process must use it, so only for the device daemon).
        allow_spinning: let idle pool workers busy-wait (only useful when one graph runs alone).
        warmup: run every loaded graph once at load, at the shapes the estimator uses.
        expected_resolution: refuse a model whose contract resolution is not this square size
            (``None``: accept any the contract allows).
        expected_variant: refuse a model of another variant (``"ghnerf"`` / ``"baseline"``).
    """

    model_dir: str = "models"
    precision: str = "auto"
    precision_overrides: Mapping[str, str] = field(default_factory=dict)
    threads: int = 2
    thread_pool: str = "per_session"
    allow_spinning: bool = False
    warmup: bool = True
    expected_resolution: int | None = None
    expected_variant: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.model_dir, (str, os.PathLike)) or not str(self.model_dir):
            _fail(type(self), "model_dir", "must be a non-empty path", self.model_dir)
        object.__setattr__(self, "model_dir", str(self.model_dir))
        _choice(self, "precision", PRECISIONS)
        if not isinstance(self.precision_overrides, Mapping):
            _fail(type(self), "precision_overrides", "must be a mapping graph -> precision", self.precision_overrides)
        for graph, prec in self.precision_overrides.items():
            if graph not in GRAPH_NAMES or prec not in ("fp32", "int8"):
                _fail(type(self), "precision_overrides", f"keys must be graphs {list(GRAPH_NAMES)} and values "
                                                         "'fp32' or 'int8'", dict(self.precision_overrides))
        object.__setattr__(self, "precision_overrides", dict(self.precision_overrides))
        _integer(self, "threads", 1, 64)
        _choice(self, "thread_pool", ("per_session", "global"))
        _boolean(self, "allow_spinning")
        _boolean(self, "warmup")
        if self.expected_resolution is not None:
            _integer(self, "expected_resolution", 64, 256)
        if self.expected_variant is not None:
            _choice(self, "expected_variant", ("ghnerf", "baseline"))


@dataclass(frozen=True)
class RoiConfig:
    """The crop window of each camera (:mod:`ghnerf_runtime.preprocess`).

    Attributes:
        volume_margin_m: metres added around the working volume for the cold-start ROI
            (training used 0).
        joint_margin_frac: tracked ROI: the joints' box grows by this fraction of its longer side
            on every side (training drew 0.10-0.35; with ``keep_frac`` the crop in use is often
            larger). 0.125 since the tenth model, whose finer trunk gains from the larger body in the
            crop: best of 0.05-0.25 on the tuning sequences (0.15 for the seventh; docs/runtime.md,
            "Re-tuning the decoder and the gates").
        min_size_px: smallest tracked ROI side, full-image pixels (training: 64).
        snap_px: tracked ROI corners and size are rounded to multiples of this (pixels), so a
            slowly moving subject reuses cached remap tables (measured on held-out sequences:
            23 % of crops reused at 1, 38 % at 4, 52 % at 8; a miss costs ~0.8 ms); 1 disables.
        keep_frac: hysteresis: the previous pair's tracked ROI is kept while the new one lies
            inside it and is at least ``1 - keep_frac`` of its size (the subject is still fully
            in view, not much smaller), so crops are stable and remap tables are reused; 0
            disables.
        map_cache_size: remap tables kept per camera (least recently used are dropped), its crop turns
            (``turn_search``) together; the working volume's (a cold pair's) are kept besides them, built with
            the estimator.
        upright: rotate each camera's crop so that the rig's down (gravity) is the picture's down, as
            in training: a camera mounted upside down (a ceiling mount), on its side or crooked. The
            angle comes from the rig file's R; free at run time (it is in the remap tables). False:
            crops keep the sensor's orientation.
        supersample: each model pixel is the box mean of ``supersample x supersample`` bilinear samples
            of the frame, as the synthetic training crops were rendered at 2x and box-reduced
            (``preprocess``, "Supersampling"); 1: the one-sample remap, blurrier than training by a
            Gaussian of sigma 0.4-0.7 model pixels on the bench rigs' crops.
        turn_search: (on by default since session 57: None, resolved by :meth:`search_for` when the estimator
            loads the model, is on for a model with encoder heatmaps, the shipped one, and off for one without,
            the baseline, which cannot score the turns; true refuses such a model, false is the opt-out.)
            On a cold pass (no track) whose result is weak (nobody found, or the found joints'
            median confidence under ``turn_search_below``), try each camera's crop turned 90, 180 and 270
            degrees more (one encoder run per turn for both views), take per view the turn whose heatmap peaks
            are clearly stronger than upright's, run the pass again with those crops and keep it when it finds
            someone more confidently, lying level or upside down across the views (``body_lie.lies_as_turned``:
            what no turn rights, a body along a line of sight, is refused); the turn stays with the track
            (upright again once it is lost) while its passes lie so, or roll on from the last one within 45
            degrees of the turn (``body_lie.lies_as_kept_turn``: someone getting up, a cartwheel). For people
            lying across the view or upside down, whom the encoder (trained on upright people) misses upright.
            A person seen by one camera only (nobody in 3D) searches only where a turn could find them in 3D:
            that view reads them weakly and the other may show them. While tracked: a weak tracked pass through
            upright crops searches the turns on its track's crops (someone who lay down); a tracked pass through a kept
            turn's crops, when weak or every ``turn_search_every``-th tracked pair, is run again through upright
            crops and the turn left when that finds the person more confidently (someone who got up); a strong
            upright tracked pass, the usual pair, pays nothing (docs/turn-search.md, "Lying and upside
            down, rendered").
        turn_search_below: the found joints' median confidence under which a pass that found someone is weak:
            a cold or upright tracked one searches, a turned tracked one is checked upright (through upright crops
            an upside-down person is read standing at 0.38 median, upright people at 0.79: docs/turn-search.md,
            "Lying and upside down, rendered"; not tuned beyond that).
        turn_search_every: after a search that kept no turn, only every this-many-th weak pair searches
            (until someone is found well): a person no turn rights (lying along the line of sight) otherwise
            makes every such pair pay three encoder runs and up to two passes more for nothing; 1: every one.
            A pair between that finds nobody where the search's pass found someone searches too, once
            (someone rolling on past what upright crops read: docs/turn-search.md, "An early search after
            a failed one").
            Also how often a tracked pass through a kept turn that is not weak is checked upright.
        edge_crop: a tracked box past the frame's edge: ``"clip"`` it to the frame and square what is left,
            ``"centre"`` square the whole box (the person centred, the part past the frame padded) or
            ``"shift"`` move that square inside the frame (``preprocess``, "Clamp / pad policy"). The
            framing changes little with the shipped model (docs/runtime.md, "A person at the frame's edge").
        pad_fill: what a crop shows past the frame's edge: ``"fade"`` (the frame's edge pixel repeated,
            fading linearly into the crop's in-frame mean colour by ``pad_fade`` crop sides out), ``"black"``
            (zeros, what a model trained with ``frame_padding`` learnt) or ``"edge"`` (the edge pixel repeated
            all the way). None (the default): the model's own, resolved when the estimator loads it
            (:meth:`fill_for`): ``"black"`` for a model whose contract says it was trained on black frame
            padding (``ghnerf.frame_padding``), ``"fade"`` for any other (the shipped model, every export
            before contract 1.3.0); a fill set here wins, and the load logs it when it is not the model's.
            With the shipped model, 3D error with 0 / 10 / 25 / 50 % of the
            person's box outside camera 0: fade 39.7 / 40.3 / 46.5 / 110.9 mm, black 54.3 / 55.9 / 64.0 / 170.6,
            edge 35.3 / 48.2 / 66.5 / 144.8 (30.6 uncut), and fade finds more joints than black at each
            (``benchmarks/measure_edge_padding.py --pad-fill fade|black|edge``; docs/runtime.md, "A person at
            the frame's edge"). A crop inside the frame is the same under any fill.
        pad_fade: ``"fade"``'s reach, crop sides past the frame's edge (0: the mean straight past it; 0.05
            and 0.2 measured worse than 0.1 at the edge or at 10-25 % out, same section).
    """

    volume_margin_m: float = 0.0
    joint_margin_frac: float = 0.125
    min_size_px: int = 64
    snap_px: int = 8
    keep_frac: float = 0.2
    map_cache_size: int = 32
    upright: bool = True
    supersample: int = 2
    turn_search: bool | None = None
    turn_search_below: float = 0.5
    turn_search_every: int = 5
    edge_crop: str = "clip"
    pad_fill: str | None = None
    pad_fade: float = 0.1

    def __post_init__(self) -> None:
        _choice(self, "edge_crop", EDGE_CROPS)
        if self.pad_fill is not None:  # None: the model's (fill_for)
            _choice(self, "pad_fill", PAD_FILLS)
        _number(self, "pad_fade", 0.0, 1.0)
        _boolean(self, "upright")
        if self.turn_search is not None:  # None: on where the model can score the turns (search_for)
            _boolean(self, "turn_search")
        _number(self, "turn_search_below", 0.0, 1.0)
        _integer(self, "turn_search_every", 1, 1000)
        _integer(self, "supersample", 1, 4)
        _number(self, "volume_margin_m", 0.0, 2.0)
        _number(self, "joint_margin_frac", 0.0, 2.0)
        _integer(self, "min_size_px", 8, 4096)
        _integer(self, "snap_px", 1, 64)
        _number(self, "keep_frac", 0.0, 0.9)
        _integer(self, "map_cache_size", 1, 4096)

    @staticmethod
    def model_fill(frame_padding: str) -> str:
        """The fill a model is fed by default, from what its training crops showed past the frame (its
        contract's ``frame_padding``): black for black (what it learnt), fade for a model whose crops never
        reached past the frame (fade measured best for the shipped one: docs/runtime.md, "A person at the
        frame's edge")."""
        return "black" if frame_padding == "black" else "fade"

    def fill_for(self, frame_padding: str) -> "RoiConfig":
        """This config with ``pad_fill`` resolved for a model trained with ``frame_padding`` (its contract's):
        the fill set here, else :meth:`model_fill`'s."""
        if self.pad_fill is not None:
            return self
        return dataclasses.replace(self, pad_fill=self.model_fill(frame_padding))

    def search_for(self, encoder_heatmaps: bool) -> "RoiConfig":
        """This config with ``turn_search`` resolved for a model with or without encoder heatmaps (its contract's
        ``encoder_heatmaps``): the value set here, else on where the model has them (the turns are scored by them;
        without, the search cannot run, and only an explicit true is refused)."""
        if self.turn_search is not None:
            return self
        return dataclasses.replace(self, turn_search=bool(encoder_heatmaps))


@dataclass(frozen=True)
class TrackingConfig:
    """Following the subject from one pair to the next (:mod:`ghnerf_runtime.tracking`).

    Attributes:
        enabled: use the previous pair's joints for the ROI and the subject box; off: always
            the working volume.
        min_joints: keep the track only when at least this many 3D joints were found
            (otherwise the next pair starts from the working volume again).
        min_confidence: joints below this confidence do not count for the track (peak values; the skeleton
            prior's joints count by their expected error instead: docs/runtime.md, "The skeleton prior").
        box_margin_m: the subject box is the tracked joints' box grown by this (the body
            reaches past its joints: head top, hands, flesh); near/far and ray limits use it.
        near_far_margin_m: extra metres around the subject box for the plane sweep's
            near/far (training: 0.1 around the body box).
        max_box_size_m: a tracked box larger than this on any axis is implausible for one
            person: the track is dropped.
        refine_cold_start: when a cold-start pair (crop and sweep from the working volume)
            yields a track, run that pair again on the subject's crop and box and report the
            second pass (costs one more keypoint pass on cold pairs only; the first pair's sweep
            spans the whole volume, coarser than the subject box the model was trained on). On by default
            since session 48: a stream's first pair after each acquisition is reported from the subject's
            crop, not the working volume's (90 still pairs: MPJPE 29.9 against 36.2 mm,
            ``benchmarks/measure_still_pairs.py --sequences 30 --every 10``), for one more keypoint pass
            on that pair alone.
        follow_encoder: with ``heatmaps.source = "rendered"``, the next crop and sweep box follow the
            joints triangulated from the encoder's own heatmaps (an output of the encoder graph the
            pair runs anyway: ~1 ms to decode and triangulate) instead of the reported joints, whose
            errors would otherwise steer the next crop off the subject. Only where to look changes;
            the reported joints stay the rendered ones. No effect with the encoder heatmaps (the
            same joints) or a model without them (docs/runtime.md, "Heatmap sources").
        retry_cold: a tracked pair that finds nobody is run again from the working volume, in the
            same pair: a subject who left the crop (a jump, a turn, a body larger than the frame) is
            found at once instead of a pair later (costs one more pass on such pairs only). A crop the
            frame check rejects counts as finding nobody (a subject who left may leave the crop a flat
            wall), unless the other camera's 2D joints were reported.
        max_gap_s: a track older than this, by the pairs' capture times (``estimate(timestamp_s=)``),
            is dropped, as is one when time runs backwards (a looped recording): the subject may be
            anywhere by now.
        cold_tiles_below_share: where the cold-start crop (the whole working volume projected) shows a 1.8 m
            person standing at the volume's centre under this share of the crop's side tall (a volume wide and
            near the cameras: the example rig's and ``ghcal synth``'s until session 68, 0.40, 51 of the model's 128
            input pixels; ``ghcal synth``'s since, 38;
            0.47 is 60 of them), a cold pair that finds
            nobody runs one more pass through one of the volume's tiles (``tracking.volume_tiles``: left/right
            halves by near/far halves, each grown 0.3 m into its neighbours), the next tile each such pair, and
            tracks from there once someone is found. The model learnt people of about 0.49 of its input and more
            (63 of 128 pixels) and misses the smaller ones (docs/runtime.md, "Cold tiles"); rigs whose cold crop
            frames that person at this or more, the bench's and the simulator's default (0.52), never run it. A
            share, not pixels, so that it means the same at any model resolution. 0 disables.
        cold_tiles_rest_every: once a whole round of tiles (each of them once, in a row) found nobody, only every
            this-many-th cold pair that finds nobody searches a tile (an empty room pays a tile pass on that share of
            its pairs, not on all); every pair searches again once a tile finds someone or a pair sees anyone
            (any joint, or a person in one view). 1 never rests (docs/runtime.md, "Cold tiles").
        cold_tiles_wake_levels: a resting search wakes (searches a tile on this pair and every cold pair after, as
            before its rest) when a camera's scene changed since the last tile pass that found nobody: a small grey
            copy of each frame (``ghnerf_runtime.scene_change``: 18 x 24 cells, each the mean of 64 sampled pixels,
            scaled to the frame's mean so that a change of exposure or light over the whole frame leaves it) differs
            from the one kept then in two cells or more by over this many 8-bit levels. Sensor noise moves a cell by
            a level or two; a person walking in, by tens. A cell that woke two searches whose round then found
            nobody (a screen, a curtain) wakes none after, nor do its neighbours, until it stays still over eight tile
            passes in a row (or a reset). 0 or None never
            wakes (docs/runtime.md, "Cold tiles").
        cold_tiles_max_foot_m: a tile's find whose lower foot stands over this many metres above the floor is refused
            (the track dropped, counted in ``Estimator.tile_finds_floating``): a person the frame's near edge cuts,
            read whole and shrunk, triangulates too far and too high. Good finds' feet read -0.16 to 0.07 m over
            three rigs, the one floating bad find 0.69 m (docs/runtime.md, "The first tile"). None keeps every find.
    """

    enabled: bool = True
    min_joints: int = 6
    min_confidence: float = 0.1
    box_margin_m: float = 0.2
    near_far_margin_m: float = 0.1
    max_box_size_m: float = 3.0
    refine_cold_start: bool = True
    follow_encoder: bool = True
    retry_cold: bool = True
    max_gap_s: float = 0.5
    cold_tiles_below_share: float = 0.47
    cold_tiles_rest_every: int = 4
    cold_tiles_wake_levels: float | None = 6.0
    cold_tiles_max_foot_m: float | None = 0.4

    def __post_init__(self) -> None:
        _boolean(self, "enabled")
        if self.cold_tiles_max_foot_m is not None:  # None: no find refused for its feet
            _number(self, "cold_tiles_max_foot_m", 0.0, 10.0)
        _number(self, "cold_tiles_below_share", 0.0, 1.0)
        _integer(self, "cold_tiles_rest_every", 1, 1000)
        if self.cold_tiles_wake_levels is not None:  # None: never wakes, as 0
            _number(self, "cold_tiles_wake_levels", 0.0, 255.0)
        _boolean(self, "retry_cold")
        _number(self, "max_gap_s", 0.0, 3600.0, lo_open=True)
        _boolean(self, "refine_cold_start")
        _boolean(self, "follow_encoder")
        _integer(self, "min_joints", 2, 25)
        _number(self, "min_confidence", 0.0, 1.0)
        _number(self, "box_margin_m", 0.0, 2.0)
        _number(self, "near_far_margin_m", 0.0, MAX_NEAR_FAR_MARGIN_M)  # the rig loader's volume check assumes it
        _number(self, "max_box_size_m", 0.1, 20.0)


@dataclass(frozen=True)
class FrameCheckConfig:
    """Cheap checks on each model input that skip the model for frames that cannot show anyone.

    Measured on the 8-bit crop (before normalisation), per camera.

    Attributes:
        enabled: run the checks.
        min_std: a crop whose standard deviation (8-bit levels) is below this is flat
            (black, saturated, lens cap): no joints from that camera.
        max_noise_ratio: share of the crop's variance that is pixel-scale detail
            (``var(x - box3(x)) / var(x)``). Measured on model inputs (session 65,
            ``benchmarks/measure_frame_check.py --sequences 30``): uniform noise 0.68-0.90 (depending
            on how the crop resamples it), the bench's frames 0.007-0.11. Above this, and above
            ``max_coarse_noise_ratio`` too, the crop is treated as noise: no joints from that camera.
        max_coarse_noise_ratio: the same share measured on the crop's 2x2 block means
            (``estimator.coarse_detail_share``), asked only of a crop above ``max_noise_ratio``. Averaging
            quarters pixel-to-pixel sensor noise and keeps a scene. Measured (session 65,
            ``benchmarks/measure_frame_check.py --sequences 30``) on the crops the fine share rejects: garbage
            (per-pixel, 2x2-block or smoothed noise) 0.64 or more; scenes with sensor noise of 40 or 60 levels
            0.33 / 0.44 at most, a sensor at 1/200 of the bench's light and gain x200 0.38 (at 1/400 and
            x400 up to 0.59, where the joints are poor anyway). 0 restores the rule before session 65 (the
            fine share alone).
        single_view_2d: when one camera's crop fails and the other's passes, still report the
            passing camera's 2D joints, from the encoder heatmaps of models that have them (one
            view gives no depth: every 3D joint is missing, and there is no novel view). Likewise
            (since session 53) a pair whose crops both pass but that shows nobody in 3D while exactly
            one view's own encoder heatmaps show someone (a person seen by that camera only): that
            camera's 2D joints (``PairResult.single_view`` names the camera). False: such pairs
            report nothing, as a pair with both crops rejected, or an empty room, does.
        volume_recheck_every: a crop on the rays of a person seen by one camera that the check rejects passes
            where that camera's whole-volume crop of the frame passes (session 70), one more preprocess a pair
            (2.0-2.4 ms at 1280 x 800, ``benchmarks/time_rays_recheck.py``). Since session 71 a verdict that
            passed answers the following pairs while the rays crop stays rejected for the same reason at much the
            same brightness, up to this many pairs in all: a covered lens is reported within this many pairs (at
            once where covering it darkened the crop, ``ghnerf_runtime.rays_recheck``). 8: within 0.27 s at 30
            pairs a second, under ``tracking.max_gap_s``, for an eighth of the cost. 1: every pair checked again
            (session 70).
        volume_recheck_levels: how far (8-bit levels) the rejected rays crop's mean may move from its mean when
            the cached verdict was taken before the camera is checked again at once: a cap or a hand over the lens
            darkens a lit wall by far more, while a plain wall seen through a moving crop keeps its level within a
            few. 0: any move checks again. A config field since session 72 (a module constant before).
    """

    enabled: bool = True
    min_std: float = 2.0
    max_noise_ratio: float = 0.3
    max_coarse_noise_ratio: float = 0.5
    single_view_2d: bool = True
    volume_recheck_every: int = 8
    volume_recheck_levels: float = 16.0

    def __post_init__(self) -> None:
        _boolean(self, "enabled")
        _boolean(self, "single_view_2d")
        _integer(self, "volume_recheck_every", 1, 1000)
        _number(self, "volume_recheck_levels", 0.0, 255.0)
        _number(self, "min_std", 0.0, 128.0)
        _number(self, "max_noise_ratio", 0.0, 1.0, lo_open=True)
        _number(self, "max_coarse_noise_ratio", 0.0, 1.0)


@dataclass(frozen=True)
class RaysConfig:
    """Which heatmap rays ``render_heat`` renders in each source view.

    Attributes:
        restrict_to_subject: render only the rays inside the projected subject box (when
            tracked); the others are heatmap 0 (what the model renders for empty rays).
        margin_cells: heatmap cells added around the projected box.
        align_cells: the rendered block's sides are rounded up to a multiple of this, so a few
            ray counts recur and onnxruntime reuses its memory plans.
    """

    restrict_to_subject: bool = True
    margin_cells: int = 2
    align_cells: int = 4

    def __post_init__(self) -> None:
        _boolean(self, "restrict_to_subject")
        _integer(self, "margin_cells", 0, 64)
        _integer(self, "align_cells", 1, 64)


#: The floor check's standing foot (Joints3DConfig.foot_standing_m) by default: the median height of a foot's
#: triangulated joints (at least two of its ankle, toes and heel) on a foot flat on the floor; the simulated people's
#: true lower foot read 0.038 m (p10 to p90 0.033 to 0.044 over the 900 pairs of
#: benchmarks/measure_calibration_drift.py --sequences 30 --frames 30; their ankles stand about 0.075 m high, toes
#: 0.04, heels 0.02). Bare feet: shoes or a mat raise it (docs/calibration.md, "Shoes, mats: the standing foot").
FOOT_STANDING_M = 0.04
#: The largest foot_standing_m accepted (metres).
MAX_FOOT_STANDING_M = 0.3


@dataclass(frozen=True)
class Joints3DConfig:
    """How 3D joints are made from the model outputs (:mod:`ghnerf_runtime.joints3d`).

    Attributes:
        method: ``"triangulate"`` (DLT of both views' 2D peaks, per-joint reprojection check;
            the default, with the default encoder heatmaps: lowest MPJPE and cost on held-out
            sequences), ``"depth_centroid"`` (heatmap-weighted centroid of the rendered depth
            points around each view's peak; the best with ``heatmaps.source = "rendered"``, see
            ``BEST_METHOD``) or ``"volumetric"`` (the ``query`` graph on a grid in the subject
            box). Comparison: ``docs/runtime.md``.
        single_view_fallback: triangulation: a joint that is not triangulated (seen in one view
            only, or the views disagree) takes the depth-centroid estimate instead, at half its
            confidence (off until measured on the trained model; docs/runtime.md). Ignored where
            the skeleton prior runs, which places those joints itself (:meth:`EstimatorConfig.beside_prior`).
        max_reprojection_px: triangulation: a joint whose reprojection error exceeds this in
            either view (model-input pixels) is missing (the views disagree).
        min_view_confidence: a 2D peak below this does not enter the 3D estimate.
        min_ray_angle_deg: triangulation: a joint whose two rays meet at less than this angle (degrees) is
            missing: its depth is meaningless (about ``sigma * Z / (f * sin(angle))``, docs/geometry.md). The
            default 0.5 is below every joint the estimator keeps on the example rig (7.5 cm baseline: 0.71 at
            the far corner of its working volume plus ``max_outside_box_m``) and above a joint 30 m from a
            10 cm baseline (0.19), which the solvers' own 0.1 (the numerically degenerate) kept. 0 turns the
            gate off, not the solvers' floor: rays on one line to rounding or from one centre give no joint
            (``geometry.triangulation.MIN_RAY_ANGLE_FLOOR_DEG``, docs/geometry.md).
        max_outside_box_m: a 3D joint further than this outside the sweep box (the tracked
            subject box, or the working volume) or outside the working volume is missing (so a
            track cannot drift out of the volume either). Two views cannot catch an error
            along the epipolar line (it only moves the point in depth); this catches the gross ones.
        grid: volumetric: about ``grid**3`` query points, in near-cubic cells over the box.
        min_volumetric_response: volumetric: a joint whose best response (mean of both
            views' sigmoid) is below this is missing.
        centroid_radius_cells: depth centroid: window half-width around the peak (heatmap cells).
        surface_offset_m: depth centroid: metres added along the ray behind the rendered surface
            (joints lie inside the body).
        skeleton_prior: triangulation: refine the triangulated joints and place the hidden ones
            with the learnt skeleton prior (``skeleton_prior.onnx`` in the model folder,
            :mod:`ghnerf_runtime.skeleton_prior`): ``"auto"`` when the model folder has one,
            ``"on"`` (a folder without one is an error) or ``"off"``. It replaces
            ``single_view_fallback``.
        max_prior_error_m: skeleton prior: a joint whose expected error (the prior's own
            estimate) exceeds this is missing (docs/runtime.md, "The skeleton prior").
        prior_flip_test: skeleton prior: also run it on the mirrored pair and average the two
            answers (in the same batch: about 0.15 ms more; docs/runtime.md, "The skeleton prior").
        max_prior_disagreement_m: skeleton prior: a pair whose prior skeleton lies further than this (the
            median distance over the triangulated joints, :func:`ghnerf_runtime.skeleton_prior.disagreement_m`)
            from the triangulation is reported as triangulated, as without the prior (``PairResult.prior_fallback``):
            the prior learnt upright people only and answers a near-upright skeleton for one lying or upside down,
            with a small expected error. ``0``, the default, turns the check off: on tracked sequences it also sends
            pairs whose triangulation is wrong to it (docs/runtime.md, "The skeleton prior"); 0.25 catches a
            person upside down.
        second_person_ratio: a view's joint map whose second-strongest peak (the decoder's ``runner_up``: another
            region's, or a second maximum past a valley in the same one) reaches this fraction of its strongest
            shows that joint twice: two people in view. On one person the shipped model's maps stay below 0.44 in
            at least one of the two views (docs/two-people.md, "Two people in the working volume").
        second_person_min_joints: a pair with at least this many joints shown twice in *both* views
            (``second_person_ratio``) is ``several_people`` (``PairResult``): its joints are kept only near the
            tracked subject's (``max_track_step_m``), or, without a track, none. So is a tracked pass whose peaks
            make a torso of two people (:func:`ghnerf_runtime.two_people.mixed_torso`; since session 58,
            docs/two-people.md, "A torso of two people"). ``0`` turns the check off, that rule with it.
        behind_min_joints: a pair whose tracked crop shows at least this many joints twice in one view alone (one
            person behind the other as the other camera sees them; docs/two-people.md, "One person behind the other")
            is ``several_people`` too; ``0`` (the default) leaves that rule out. Off because one person alone
            reaches it: through the shipped model 5 of the bench's 300 pairs (10 sequences) were flagged with 6,
            PCK@0.2 0.981 -> 0.979, and a person lying or upside down read through upright crops on up to 11 of 72
            pairs, while the model's own gain with a person behind was small (1 m behind: 11 % of pairs flagged,
            104.5 -> 95.2 mm); the oracle's figures in that section are with 6.
        max_track_step_m: in a ``several_people`` pair, a joint further than this from the tracked subject's place
            for it (the previous pair's) is missing: it is the other person's, or triangulated from one person's
            peak in one view and the other's in the other. With the triangulation, the pairing of the views' peaks
            and runner-ups (``Keypoints2D.runner_up_uv``) nearest the track within this is reported instead.
        pick_subject: a ``several_people`` pair without a track (two people from the first pair, or the track lost
            while both are there), with the triangulation: the two people are separated
            (:mod:`ghnerf_runtime.two_people`) and one is reported, and then tracked: ``"centre_line"`` (the
            default) the one nearest the rig's centre line (the floor line from below the cameras' midpoint
            through the working volume's centre), within 0.2 m of each other the one nearer the cameras;
            ``"nearest"`` the one nearest the cameras, within 0.2 m the one nearer the centre line; ``"none"``
            nobody until one is alone (session 53's rule; docs/two-people.md, "Two people without a track").
        foot_standing_m: the floor check's foot height (``PairResult.lowest_foot_m``, the daemon's ``FloorWatch``) is
            the median height of the lower foot's triangulated joints less this (metres): that median on a foot
            standing flat on this install's floor. The default is the simulated people's bare feet
            (:data:`FOOT_STANDING_M`); shoes' soles or a mat raise it by their thickness, which the floor check's
            limit (``health.calibration_max_floor_m``, 0.05 m) would otherwise absorb: ``ghnerf-daemon --config
            FILE --measure-floor`` measures it on the rig (docs/calibration.md, "Shoes, mats: the standing foot").
    """

    method: str = "triangulate"
    single_view_fallback: bool = False
    max_reprojection_px: float = 6.0
    min_view_confidence: float = 0.1
    min_ray_angle_deg: float = 0.5
    max_outside_box_m: float = 0.5
    grid: int = 16
    min_volumetric_response: float = 0.1
    centroid_radius_cells: int = 2
    surface_offset_m: float = 0.03
    skeleton_prior: str = "auto"
    max_prior_error_m: float = 0.15
    prior_flip_test: bool = True
    max_prior_disagreement_m: float = 0.0
    second_person_ratio: float = 0.5
    second_person_min_joints: int = 6
    behind_min_joints: int = 0
    max_track_step_m: float = 0.15
    pick_subject: str = "centre_line"
    foot_standing_m: float = FOOT_STANDING_M

    def __post_init__(self) -> None:
        _choice(self, "method", THREE_D_METHODS)
        _choice(self, "skeleton_prior", SKELETON_PRIOR_MODES)
        if self.skeleton_prior == "on" and self.method != "triangulate":  # not "the folder has none" at load
            _fail(type(self), "skeleton_prior", f"'on' needs method 'triangulate' (the prior refines triangulated "
                                                f"joints; method is {self.method!r})", self.skeleton_prior)
        _number(self, "max_prior_error_m", 0.0, 100.0, lo_open=True)
        _boolean(self, "prior_flip_test")
        _number(self, "max_prior_disagreement_m", 0.0, 100.0)
        _boolean(self, "single_view_fallback")
        _number(self, "max_reprojection_px", 0.0, 1000.0, lo_open=True)
        _number(self, "min_view_confidence", 0.0, 1.0)
        _number(self, "min_ray_angle_deg", 0.0, 90.0)  # the solvers' own range (the angle between lines)
        _number(self, "max_outside_box_m", 0.0, 100.0)
        _integer(self, "grid", 4, 48)
        _number(self, "min_volumetric_response", 0.0, 1.0)
        _integer(self, "centroid_radius_cells", 0, 8)
        _number(self, "surface_offset_m", -0.5, 0.5)
        _number(self, "second_person_ratio", 0.0, 1.0, lo_open=True)
        _integer(self, "second_person_min_joints", 0, 25)
        _integer(self, "behind_min_joints", 0, 25)
        _number(self, "max_track_step_m", 0.0, 10.0, lo_open=True)
        _choice(self, "pick_subject", PICK_SUBJECT_RULES)
        # up to 0.3 m: bare feet to a thick mat under thick soles; more is a floor the rig file has wrong
        _number(self, "foot_standing_m", 0.0, MAX_FOOT_STANDING_M)

    def uses_skeleton_prior(self, available: bool) -> bool:
        """Whether the skeleton prior runs, given whether the model folder has one (``on`` without one is the
        estimator's error to raise)."""
        return available and self.skeleton_prior != "off" and self.method == "triangulate"


#: Presence gate defaults per heatmap source (``PresenceConfig.min_confidence`` None): between the
#: 6th-strongest 3D joint of empty-room pairs (encoder <= 0.25, rendered <= 0.33 over 32 rooms) and of
#: pairs with a person (encoder >= 0.52; rendered: 37 of 40 pairs >= 0.52, 3 pairs of one sequence whose
#: crop drifted <= 0.11) on held-out sequences with the shipped (sixth) model of 2026-11-22
#: (benchmarks/measure_presence.py --rooms 32). The encoder gate was 0.3 for the fifth model (rooms
#: <= 0.16); the rendered one 0.475 for the models before the fifth. Those rooms were black frames; textured empty
#: rooms (since session 65) with the shipped tenth model: encoder no joint found, rendered <= 0.23 (docs/runtime.md,
#: "Missing joints, never stale ones").
PRESENCE_MIN_CONFIDENCE = {"encoder": 0.35, "rendered": 0.4}


@dataclass(frozen=True)
class PresenceConfig:
    """Whether a pair shows a person at all.

    A model trained only on people answers "someone" for an empty room too (phantom joints with
    weak peaks). A pair counts as showing a person only when at least ``min_joints`` of its 3D
    joints have confidence ``>= min_confidence``; otherwise every joint (3D and 2D) is reported
    missing and the track is dropped, unless exactly one view's own encoder heatmaps show someone
    (``min_joints`` peaks at the encoder threshold): that camera's 2D joints then
    (``FrameCheckConfig.single_view_2d``).

    Attributes:
        enabled: apply the gate.
        min_joints: strong joints needed.
        min_confidence: confidence of a strong joint; ``None`` takes the measured default of the
            heatmap source (``PRESENCE_MIN_CONFIDENCE``).
        scan_every_s: while tracking, every this many seconds of capture time, run the keypoint graph once on
            the whole working volume and ask whether anyone besides the subject is there
            (:mod:`ghnerf_runtime.others_scan`, ``PairResult.someone_else``; on the joint stream the SOMEONE_ELSE
            flag, announced in HELLO only while this is set); 0 (the default): never.
    """

    enabled: bool = True
    min_joints: int = 6
    min_confidence: float | None = None
    scan_every_s: float = 0.0

    def __post_init__(self) -> None:
        _boolean(self, "enabled")
        _integer(self, "min_joints", 1, 25)
        if self.min_confidence is not None:
            _number(self, "min_confidence", 0.0, 1.0)
        _number(self, "scan_every_s", 0.0, 3600.0)

    def threshold(self, source: str) -> float:
        return PRESENCE_MIN_CONFIDENCE[source] if self.min_confidence is None else float(self.min_confidence)


@dataclass(frozen=True)
class SmoothingConfig:
    """Temporal smoothing of the reported 3D joints (:mod:`ghnerf_runtime.smoothing`: a One Euro filter
    per joint on the pairs' capture times). On by default: on the bench it lowers both the jitter and the
    MPJPE (docs/runtime.md, "Smoothing", has the trade and the other settings). It needs the pairs'
    capture times (``Estimator.estimate(timestamp_s=)``); a pair without one is reported unsmoothed.

    Attributes:
        enabled: smooth the reported joints (the tracker always follows the raw ones).
        min_cutoff_hz: the cutoff of a still joint (lower: steadier, more lag); :data:`MIN_CUTOFF_HZ` at least.
        beta: how fast the cutoff rises with the joint's speed, Hz per m/s (higher: less lag when moving).
        d_cutoff_hz: the cutoff of the speed estimate; :data:`MIN_CUTOFF_HZ` at least.
        max_gap_s: a longer gap between pairs restarts every joint.
    """

    enabled: bool = True
    min_cutoff_hz: float = 1.0
    beta: float = 10.0  # tuned: the most jitter cut while the MPJPE still falls; 30 lags less (docs/runtime.md)
    d_cutoff_hz: float = 1.0
    max_gap_s: float = 0.25

    def __post_init__(self) -> None:
        _boolean(self, "enabled")
        # A cutoff below MIN_CUTOFF_HZ is a time constant of minutes to ages: the filter holds its first pair for the
        # stream, and below about 1e-308 Hz the time constant overflowed (numpy warned in the log on every pair).
        _number(self, "min_cutoff_hz", MIN_CUTOFF_HZ, 1000.0)
        _number(self, "beta", 0.0, 1e4)
        _number(self, "d_cutoff_hz", MIN_CUTOFF_HZ, 1000.0)
        _number(self, "max_gap_s", 0.0, 60.0, lo_open=True)


HEATMAP_SOURCES = ("rendered", "encoder")


@dataclass(frozen=True)
class HeatmapsConfig:
    """Where the source views' joint heatmaps come from.

    Attributes:
        source: ``"encoder"`` (the default: the human encoder's own 2D heatmaps, an output of the
            ``encoder`` graph, and of the ``human`` graph alone, of models exported with
            ``encoder_heatmaps``; ``volume`` and ``render_heat`` then run only where the 3D
            method needs them: ``depth_centroid`` and
            the single-view fallback read the rendered depth, ``volumetric`` the volume) or
            ``"rendered"`` (GHNeRF: volume-rendered by ``render_heat`` from the cost volume, the
            human features and the heads; ``volume`` and ``render_heat`` run every pair; models
            without encoder heatmaps, e.g. the baseline, need it). With the shipped model the
            encoder's are more accurate and ~2x faster (measured in docs/runtime.md).
        flip_test: with the encoder heatmaps, also run the human encoder on the mirrored crops and
            average the two estimates (:mod:`ghnerf_runtime.flip_test`). On by default: on 30
            held-out-like sequences PCK@0.2 0.905 -> 0.921 and MPJPE 118.6 -> 106.4 mm (85.5 mm
            over the joints both cameras see, from 101.2), the body taken the wrong way round in
            1.9 % of the pairs instead of 2.9 %; held out, view 1's PCK 0.899 -> 0.913. It costs a
            second human-graph run: keypoints 4.2 -> 5.1 ms median on a fast 2-core host, 9.9 ->
            14.1 on a slower one (docs/runtime.md, "Flip test"). False saves that where latency
            matters more. No effect on rendered heatmaps.
        flip_test_skip_below: the flip test's second run is skipped for a pair in which, without it,
            fewer than ``presence.min_joints`` joints reach this peak value in both views (the
            geometric mean of the views' heatmap maxima; in one view on the single-view path), nor,
            with ``frame_check.single_view_2d``, in either view alone (a person seen by one camera
            only): nobody is there, and the presence gate would say so with the mirrored run too. An empty room then
            costs one encoder run, not two. Only while the presence gate is on; 0 always runs it.
            With the shipped model, 32 textured empty rooms (frame check off) reach <= 0.010 and 40 held-out
            pairs with a person >= 0.79 (``benchmarks/measure_presence.py --rooms 32 --flip-test``, session 65).
        flip_test_side_by_side: on a tracked pair (someone was there), run the ``human`` graph on the crops and
            on their mirror images side by side, one thread each (``ModelSession.run_both``), not one after
            the other on two threads; the same heatmaps, sooner (docs/runtime.md, "Flip test"). Only with a
            pool of two or more threads per session (``session.threads``, ``thread_pool: "per_session"``);
            cold pairs run in turn, so the skip above still applies to them.
    """

    source: str = "encoder"
    flip_test: bool = True
    flip_test_skip_below: float = 0.1
    flip_test_side_by_side: bool = True

    def __post_init__(self) -> None:
        _choice(self, "source", HEATMAP_SOURCES)
        _boolean(self, "flip_test")
        _number(self, "flip_test_skip_below", 0.0, 1.0)
        _boolean(self, "flip_test_side_by_side")


#: The best 3D method of each heatmap source on held-out sequences (docs/runtime.md, 3D methods).
BEST_METHOD = {"encoder": "triangulate", "rendered": "depth_centroid"}


@dataclass(frozen=True)
class NovelViewConfig:
    """Novel-view rendering (:mod:`ghnerf_runtime.novel_view`).

    Attributes:
        enabled: load the colour graph(s) so novel views can be requested. When off, no colour
            graph is loaded or run.
        stride: render every ``stride``-th pixel (1: the full contract resolution; 2: a quarter
            of the rays, upsampled); must divide the model resolution (the estimator checks it at load).
        heatmaps: also render joint heatmaps at the novel camera (``render`` graph: colour and
            heatmaps in one pass; costs more).
        rays_in_box_only: render only the rays inside the projected subject box (the rest is
            background).
        crop_to_subject: a requested camera is cropped (in its own image) to the subject, as
            the model sees the sources; off: its whole image is resized to the model resolution.
        path: how a view between the rig's cameras (``NovelViewRequest.alpha``) moves from one to the other.
            ``"line"``: its centre on the straight line between theirs (crosses the subject when they face
            each other); ``"orbit"``: on an arc round the point nearest both optical axes, its distance to it
            lerped (the subject box's centre when the axes are parallel or that point lies behind a camera;
            the line when that is behind one too); ``"auto"``: the orbit when the optical axes are more than
            ``novel_view.AUTO_ORBIT_MIN_ANGLE_DEG`` (60) degrees apart, else the line. Its rotation is
            slerped either way (docs/novel-view.md, "Between the cameras: a line or an orbit").
        silhouette_stride: coarse-to-fine in the image: a first pass renders every
            ``silhouette_stride``-th pixel of the box, and only the cells where it finds the subject (plus
            ``silhouette_dilate`` cells around them) are rendered at ``stride``; the rest is
            background. The person fills a fraction of its box, so this renders fewer rays
            (measured in docs/runtime.md). 0: off (every ray of the box); one of 0, 1, 2, 4, 8, 16 (it must
            divide the model resolution: the estimator checks it against the model's); a multiple of
            ``stride`` larger than it, else the coarse pass is skipped.
        silhouette_min_diff: a coarse cell counts as the subject when its colour differs from the
            background by this much (max over RGB, [0, 1] units; 0.05 = 13 grey levels). Colour,
            not opacity: the model may render empty space as opaque background.
        silhouette_dilate: coarse cells added around the subject's (thin limbs between
            coarse rays, the soft edge).
        interior_stride: with the coarse pass, the subject's *interior* (coarse cells whose eight
            neighbours are the subject too) is rendered every ``interior_stride``-th pixel and
            filled in bilinearly; its edge cells are rendered at ``stride``. The edges of the
            silhouette, where the picture changes fastest, keep full resolution; what the interior
            loses against every ray is measured in docs/runtime.md. Applies when larger than
            ``stride``; must divide ``silhouette_stride`` and the model resolution (checked at load).
            0: off (every subject cell at ``stride``).
        overlap: on a tracked pair, render the novel view in a worker thread while this pair's
            keypoints are decoded and triangulated (onnxruntime releases the GIL; its render
            graphs gain little from the second core, measured in docs/runtime.md). The view is
            then cropped to the tracked subject box (the previous pair's joints plus the
            tracking margin) instead of this pair's joints, which are not known yet. Off, or on
            a cold pair: the view follows the keypoints, cropped to this pair's joints.
        lanes: with ``overlap``, the worker renders on one-thread sessions of the view's graphs and starts as soon
            as the encoder graph has run, the flip test's run going beside it on one thread too: two threads on
            the two cores rather than four (a two-thread run waits for its slower thread). Only where the graphs
            have a pool of their own of two threads or more (``session.thread_pool`` "per_session"); the same
            pictures (docs/runtime.md, "The novel view alongside the keypoints"). Off: the view starts after the
            flip test and renders on the graphs' own sessions.
        opaque_at: a ray whose accumulated opacity reaches this counts as opaque in the picture:
            its colour is the composite divided by the opacity (the subject's own colour), and a
            fainter ray keeps ``opacity / opaque_at`` of it over the background. The model leaves
            the subject slightly transparent (opacity about 0.9), which dims it over the black
            background; the floor keeps faint fog faint (at most ``1 / opaque_at`` brighter).
            Tuned on the ``val_seen_motions`` split, measured on the device's views in
            docs/runtime.md ("Novel-view quality"). 1.0: the raw composite.
        proxy_blend: recolour the subject from the source crops at the depth of a body proxy built from
            the pair's 3D joints (``ghnerf_runtime.proxy_blend``): the pixels the rendered picture shows
            as the subject, the proxy covers and some source sees get those sources' pixels, weighted
            by how near each source's ray is to the view's; the rest keep the rendered picture. The
            proxy's depth is nearer the truth than the model's: on by default since session 29, +0.5
            to +2.1 dB median against the simulator's picture, at about 12 ms per view on a 2-core
            host (docs/novel-view.md, "Recolouring from the body proxy"). Off: the rendered picture alone.
        proxy_tolerance_m: with ``proxy_blend``, a source sees a surface point when the proxy's own
            depth in that source is this close to the point's (metres).
        proxy_max_angle_deg: with ``proxy_blend``, a pixel is recoloured only when a source that sees its
            point looks at it within this angle of the view's ray: views from far round the subject
            are better left to the network, and to the painter (30 since session 30, 60 before:
            docs/novel-view.md, "The learnt painter").
        painter: repaint the subject with the learnt painter (``novel_painter.onnx`` in the model
            folder, :mod:`ghnerf_runtime.novel_painter`) over the body proxy of the pair's joints,
            before ``proxy_blend``: ``"auto"`` when the model folder has one, ``"on"`` (a folder
            without one is an error) or ``"off"`` (docs/novel-view.md, "The learnt painter").
        painter_min_angle_deg: the painter runs only on views at least this far (degrees, at the
            subject's centre) from the nearest source camera: nearer, the sources see nearly all the
            view sees and the proxy blend does as well at a fraction of its cost (docs/novel-view.md, "The
            learnt painter"). 0: every view.
        matte: fade the view to the background away from the body proxy of the pair's joints
            (``ghnerf_runtime.proxy_matte``): the coloured fog the model leaves around the subject goes,
            at the cost of subject pixels the proxy misses by more than the margin. On by default since
            session 31: held out, PSNR over the whole view +1.4 dB at the rig's cameras and +2.0 dB on
            ``ghnerf-eval``'s views round the subject, masked PSNR -0.3 and -0.17 dB; on the device's
            views through the runtime +0.7 to +0.8 dB whole, -0.07 to -0.19 dB masked (medians;
            docs/novel-view.md, "Matting out the fog"). The parts of joints not found are kept within their
            reach; where the picture disagrees with the proxy (wrong joints), nothing is matted.
        matte_margin_m: with ``matte``, pixels within this distance (metres, at the proxy's depth) of
            the proxy's silhouette keep the picture.
        matte_feather_m: with ``matte``, beyond the margin the picture fades to the background over
            this distance (metres; 0: a hard edge).
    """

    enabled: bool = False
    stride: int = 1
    heatmaps: bool = False
    rays_in_box_only: bool = True
    crop_to_subject: bool = True
    path: str = "auto"
    silhouette_stride: int = 4
    silhouette_min_diff: float = 0.05
    silhouette_dilate: int = 0
    interior_stride: int = 0
    overlap: bool = True
    lanes: bool = True
    opaque_at: float = 0.5
    proxy_blend: bool = True
    proxy_tolerance_m: float = 0.03
    proxy_max_angle_deg: float = 30.0
    painter: str = "auto"
    painter_min_angle_deg: float = 15.0
    matte: bool = True
    matte_margin_m: float = 0.08
    matte_feather_m: float = 0.15

    def __post_init__(self) -> None:
        _boolean(self, "enabled")
        _boolean(self, "matte")
        _number(self, "matte_margin_m", 0.0, 1.0)
        _number(self, "matte_feather_m", 0.0, 1.0)
        _choice(self, "painter", ("auto", "on", "off"))
        _number(self, "painter_min_angle_deg", 0.0, 180.0)
        _boolean(self, "proxy_blend")
        _number(self, "proxy_tolerance_m", 0.001, 0.5)
        _number(self, "proxy_max_angle_deg", 0.0, 180.0)
        _number(self, "opaque_at", 0.05, 1.0)
        _integer(self, "stride", 1, 4)
        _choice(self, "stride", (1, 2, 4))
        _boolean(self, "heatmaps")
        _boolean(self, "rays_in_box_only")
        _boolean(self, "crop_to_subject")
        _choice(self, "path", NOVEL_PATHS)
        _boolean(self, "overlap")
        _boolean(self, "lanes")
        _integer(self, "silhouette_stride", 0, 16)
        # the coarse grid must tile the model resolution, else its cells refined to `stride` miss the image's
        # last rows (6 at 128: 21 cells -> 126 pixels) and the render fails on the mismatch
        _choice(self, "silhouette_stride", NOVEL_SILHOUETTE_STRIDES)
        if self.silhouette_stride and self.silhouette_stride % self.stride:
            _fail(type(self), "silhouette_stride", f"must be 0 or a multiple of stride ({self.stride})",
                  self.silhouette_stride)
        _number(self, "silhouette_min_diff", 0.0, 1.0)
        _integer(self, "silhouette_dilate", 0, 8)
        _integer(self, "interior_stride", 0, 8)
        _choice(self, "interior_stride", (0, 1, 2, 4, 8))
        if self.interior_stride and self.silhouette_stride and self.silhouette_stride % self.interior_stride:
            _fail(type(self), "interior_stride", f"must divide silhouette_stride ({self.silhouette_stride})",
                  self.interior_stride)

    def uses_painter(self, available: bool) -> bool:
        """Whether the learnt painter runs, given whether the model folder has one (``on`` without one is the
        estimator's error to raise)."""
        return available and self.enabled and self.painter != "off"

    @property
    def coarse_pass(self) -> bool:
        """Whether a coarse pass picks the rays (see ``silhouette_stride``)."""
        return self.silhouette_stride > self.stride

    @property
    def interior_pass(self) -> bool:
        """Whether the subject's interior is rendered sparser than its edges (see ``interior_stride``)."""
        return self.coarse_pass and self.interior_stride > self.stride


@dataclass(frozen=True)
class EstimatorConfig:
    """The root: everything :class:`ghnerf_runtime.estimator.Estimator` needs besides the rig."""

    session: SessionConfig = field(default_factory=SessionConfig)
    roi: RoiConfig = field(default_factory=RoiConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    frame_check: FrameCheckConfig = field(default_factory=FrameCheckConfig)
    rays: RaysConfig = field(default_factory=RaysConfig)
    decoder: KeypointDecoderConfig = field(default_factory=KeypointDecoderConfig)
    heatmaps: HeatmapsConfig = field(default_factory=HeatmapsConfig)
    joints3d: Joints3DConfig = field(default_factory=Joints3DConfig)
    presence: PresenceConfig = field(default_factory=PresenceConfig)
    novel_view: NovelViewConfig = field(default_factory=NovelViewConfig)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            kind = typing.get_type_hints(type(self))[f.name]
            if not isinstance(getattr(self, f.name), kind):
                _fail(type(self), f.name, f"must be a {kind.__name__}", getattr(self, f.name))

    def beside_prior(self, prior_available: bool) -> "EstimatorConfig":
        """This configuration as it runs, given whether the model folder has a skeleton prior: the prior places
        the joints ``single_view_fallback`` would (it replaces it), so where the prior runs the fallback is off,
        and its two graphs (``volume``, ``render_heat``) are neither loaded nor run for nothing."""
        j = self.joints3d
        if j.single_view_fallback and j.uses_skeleton_prior(prior_available):
            return dataclasses.replace(self, joints3d=dataclasses.replace(j, single_view_fallback=False))
        return self

    def beside_model(self, frame_padding: str, encoder_heatmaps: bool | None = None) -> "EstimatorConfig":
        """This configuration as it runs with a model trained with ``frame_padding`` (its contract's): an unset
        ``roi.pad_fill`` becomes the model's own (:meth:`RoiConfig.fill_for`); given ``encoder_heatmaps`` (whether
        the model has them, its contract's), an unset ``roi.turn_search`` too (:meth:`RoiConfig.search_for`)."""
        roi = self.roi.fill_for(frame_padding)
        if encoder_heatmaps is not None:
            roi = roi.search_for(encoder_heatmaps)
        return self if roi is self.roi else dataclasses.replace(self, roi=roi)

    def required_graphs(self, human_graph: bool = False) -> tuple[str, ...]:
        """The graphs this configuration runs (the session loads only these).

        ``human_graph``: the model has a ``human`` graph (contract 1.2.0). A configuration that reads
        the encoder heatmaps and builds no source volume then runs it for the keypoints, and loads
        ``encoder`` only when novel views need the image features.
        """
        human = self.uses_human_graph(human_graph)
        # the flip test's second pass needs the encoder heatmaps alone: the human graph when there is one
        graphs = ["human"] if human or (human_graph and self.flips_encoder_heatmaps) else []
        if not human or self.novel_view.enabled:
            graphs.insert(0, "encoder")
        if self.runs_source_volume or self.novel_view.enabled:
            graphs.append("volume")
        if self.renders_source_heatmaps:
            graphs.append("render_heat")
        if self.joints3d.method == "volumetric":
            graphs.append("query")
        if self.novel_view.enabled:
            graphs.append("render" if self.novel_view.heatmaps else "render_rgb")
        return tuple(graphs)

    @property
    def renders_source_heatmaps(self) -> bool:
        """Whether each pair runs ``volume`` + ``render_heat`` in the source views: for the heatmaps
        themselves, or for the rendered depth the 3D method reads."""
        j = self.joints3d
        return (self.heatmaps.source == "rendered" or j.method == "depth_centroid"
                or (j.method == "triangulate" and j.single_view_fallback))

    @property
    def flips_encoder_heatmaps(self) -> bool:
        """Whether each pair also runs the human encoder on the mirrored crops (``heatmaps.flip_test``)."""
        return self.heatmaps.source == "encoder" and self.heatmaps.flip_test

    def uses_human_graph(self, human_graph: bool) -> bool:
        """Whether the keypoint pass runs the ``human`` graph (when the model has one) instead of ``encoder``:
        only the encoder heatmaps are read and no source volume needs the image features."""
        return human_graph and self.heatmaps.source == "encoder" and not self.runs_source_volume

    @property
    def runs_source_volume(self) -> bool:
        """Whether each pair builds the cost volume of the source views (for rendering or ``query``)."""
        return self.renders_source_heatmaps or self.joints3d.method == "volumetric"


# ------------------------------------------------------------------ dict I/O
def _build(cls: type, data: Any, path: str) -> Any:
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        # the root has no key: keyed by its class, the daemon reported "estimator.EstimatorConfig: ..."
        raise ConfigError(f"must be a mapping (JSON object), got {type(data).__name__}", key=path or None)
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            where = f"{path}.{key}" if path else str(key)
            raise ConfigError(f"unknown key; {cls.__name__} has {sorted(names)}", key=where)
    kwargs = {}
    for key, value in data.items():
        where = f"{path}.{key}" if path else key
        kind = hints[key]
        if dataclasses.is_dataclass(kind):
            kwargs[key] = _build(kind, value, where)
        elif isinstance(value, list):
            kwargs[key] = tuple(value)
        else:
            kwargs[key] = value
    try:
        return cls(**kwargs)
    except ConfigError as e:
        # Re-key "ClassName.field" as the dotted path the user wrote.
        field_name = (e.key or "").split(".")[-1]
        where = f"{path}.{field_name}" if path else field_name
        raise ConfigError(str(e).split(": ", 1)[-1], key=where) from None
    except KeypointConfigError as e:  # keyed by the dotted path the user wrote, as the other sections are
        where = ".".join(k for k in (path, e.field) if k) or cls.__name__
        raise ConfigError(str(e).split(": ", 1)[-1] if e.field else str(e), key=where) from None


def config_from_dict(data: Mapping[str, Any]) -> EstimatorConfig:
    """Build and validate the whole tree from plain data; unknown keys raise :class:`ConfigError`.

    Example:
        >>> config_from_dict({"joints3d": {"method": "volumetric"}}).joints3d.method
        'volumetric'
        >>> config_from_dict({"joints3d": {"metod": "x"}})
        Traceback (most recent call last):
        ...
        ghnerf_runtime.errors.ConfigError: joints3d.metod: unknown key; Joints3DConfig has [...]
    """
    return _build(EstimatorConfig, data, "")


def config_to_dict(config: Any) -> dict:
    """The tree as plain data (JSON-ready); ``config_from_dict(config_to_dict(c)) == c``."""
    out = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            value = config_to_dict(value)
        elif isinstance(value, tuple):
            value = list(value)
        elif isinstance(value, Mapping):
            value = dict(value)
        out[f.name] = value
    return out


def _plain_json(value: Any) -> Any:
    """``value`` with plain dicts for the :class:`~ghnerf_runtime.json_keys.KeysObject` the parse made."""
    if isinstance(value, dict):
        return {k: _plain_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain_json(v) for v in value]
    return value


def _json_given_as_path(path: str | os.PathLike) -> str:
    """What to add to "cannot read" when the path is JSON text itself (``--config '{"roi": ...}'``, as a doc's
    "``--config`` with ``{...}``" reads), else ""."""
    if str(path).lstrip().startswith(("{", "[")):
        return ": a file's path is expected, not the JSON itself: write it into a file and give the file's path"
    return ""


def read_json_file(path: str | os.PathLike, fail: Callable[[str], Exception], what: str = "config file",
                   max_chars: int | None = None) -> Any:
    """The JSON value in ``path``; an unreadable file, invalid JSON, non-UTF-8 text or a key given twice in one
    object (JSON keeps the last: the first would be lost without a word) raises ``fail(message)`` (the caller's
    error type, naming the file), the message saying which and where; so does an empty (or blank) file. A UTF-8
    byte order mark is skipped. With ``max_chars``, text longer than that raises ``fail`` after reading at most one
    character more: a pipe or a file that grows is not read whole (a size told by ``stat`` can change before the
    read, and a pipe has none)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            text = fh.read() if max_chars is None else fh.read(max_chars + 1)
    except OSError as e:
        raise fail(f"cannot read {what} ({e.strerror or e}){_json_given_as_path(path)}") from e
    except UnicodeDecodeError as e:
        raise fail(f"not UTF-8 text (byte {e.start}): {e.reason}") from e
    except ValueError as e:  # a NUL character in the path
        raise fail(f"cannot read {what} ({e})") from e
    if max_chars is not None and len(text) > max_chars:
        raise fail(f"{what} holds over {max_chars} characters, more than one may")
    if not text.strip():  # said "not valid JSON (line 1, column 1: Expecting value)"
        raise fail(f"{what} is empty")
    try:
        data = loads_remembering(text)
    except JsonTextError as e:  # invalid, nested thousands deep, or an integer past 4300 digits
        where = "" if e.line is None else f"line {e.line}, column {e.column}: "
        raise fail(f"not valid JSON ({where}{e.reason})") from e
    repeated = first_repeat(data)
    if repeated is not None:
        raise fail(f"duplicate key {repeated!r} (JSON keeps only its last value)")
    return _plain_json(data)


def load_config(path: str | os.PathLike) -> EstimatorConfig:
    """Read a JSON config file; errors name the file and the key. A relative ``session.model_dir`` in the
    file is read from the file's folder (:mod:`ghnerf_runtime.config_paths`)."""
    data = read_json_file(path, lambda message: ConfigError(message, key=str(path)))
    impossible = impossible_path(data, PATH_KEYS)
    if impossible is not None:
        raise ConfigError(f"{impossible[0]}: {impossible[1]}", key=str(path))
    try:
        return config_from_dict(paths_from_file(data, PATH_KEYS, path))
    except ConfigError as e:
        raise ConfigError(str(e), key=str(path)) from None
