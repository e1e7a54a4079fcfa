"""The code's constants and lists that the docs quote, quoted as they are.

Each of these was written into a doc by hand beside a change of the code (session 50); a later change of the
constant would leave the doc stating the old value without a word. (The runtime's defaults JSON is checked by
``tests/ghnerf_runtime/test_cli_run.py``, the daemon configs in the docs by
``tests/firmware_host/daemon/test_daemon_config.py``, which also holds the daemon's defaults table to the dataclasses.)
"""
from __future__ import annotations

import inspect
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.empty_rooms import SCREEN_BLOCKS
from benchmarks.measure_two_people import OWN_PEAK_CELLS
from calibration.board import MIN_CORNERS, BoardSpec
from calibration.check import CheckLimits
from calibration.cli import STALL_NOTE_S
from calibration.capture import MISMATCH_TRIES
from calibration.consensus import CONSENSUS_DEG, CONSENSUS_MM
from calibration.formats.opencv_yaml import _SAME_POSE_TOLERANCE, _SAME_T_TOLERANCE
from calibration.solve import COVERAGE_GRID, MIN_VIEWS, REPEAT_PX, USUAL_PITCH_DEG
from calibration.detect import PATTERN_CHECK_MARKERS
from calibration.render import SYNTH_BOARD, SYNTH_CAMERA_HEIGHT_M, SYNTH_PITCH_DEG, SYNTH_VOLUME_NEAR_M
from drivers.backends.depthai.options import DEFAULT_MOUNT_HEIGHT_M, DepthaiOptions
from drivers.backends.depthai.source import SLOW_SHARE
from drivers.backends.replay import MENDED_RUN, MIN_SPEED
from drivers.url import whole_number
from drivers.url_paths import FILE_PARTS
from firmware_host.daemon.calibration_watch import CLEAR_RATIO
from firmware_host.daemon.config import MAX_CONFIG_FILE_BYTES
from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M, CALIBRATION_MAX_MIRROR, CALIBRATION_MAX_PX, \
    CALIBRATION_WINDOW, DAEMON_PATH_KEYS
from firmware_host.daemon.measure_floor import DEFAULT_PAIRS, READS_PER_PAIR
from firmware_host.daemon.health import STATUS_KEEP, STATUS_MAX, STATUS_RELOAD_MAX
from firmware_host.daemon.memory import MMAP_THRESHOLD
from firmware_host.daemon.notify import STATE_RETRY_S
from firmware_host.daemon.rig_open import POLL_S
from firmware_host.daemon.sandbox import HOME_FOLDERS, PRIVATE_TMP_FOLDERS
from firmware_host.daemon.service import MAX_FAILED_RUNS, SIZE_MISMATCH_OPENS
from firmware_host.listen import LATE_WINDOW, MAX_PRODUCERS, QUIET_S, SENDER_KEY
from firmware_host.protocol.constants import MAX_JOINTS, NO_FRAME_SEQ
from firmware_host.protocol.quantize import _I16_MAX, _I16_MIN, _MM_PER_M
from firmware_host.sinks.options import MAX_QUEUE, MAX_STALL_S, MAX_STATUS_S, MIN_STALL_S, MIN_STATUS_S, SinkOptions
from firmware_host.sinks.rate import MIN_MAX_FPS
from firmware_host.sinks.serial_sink import CLOSE_DRAIN_S
from firmware_host.sinks.udp_sink import MIN_RESOLVE_S, REFUSAL_ANSWER_S, REFUSAL_QUIET_S, RESOLVE_S
from firmware_host.sinks.url import MAX_HOST_NAME
from firmware_host.sinks.vmc_time import DEFAULT_FPS, JUMP_FRAMES, NEW_TIMELINE_FRAMES, STEPS_KEPT
from firmware_host.sinks.vmc_view import FACINGS
from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.config import FOOT_STANDING_M, MAX_FOOT_STANDING_M, MIN_CUTOFF_HZ, Joints3DConfig, RoiConfig, \
    TrackingConfig
from ghnerf_runtime.handedness import LYING_BAND_DEG, MAX_TORSO_SPAN_M, MIN_LEFT_SPAN_M
from ghnerf_runtime.contract import MAX_DEPTH_M, MAX_NEAR_FAR_MARGIN_M, WEIGHTS_ID_KEY
from ghnerf_runtime.body_lie import KEPT_TURN_SECTOR_DEG, KEPT_TURN_STEP_DEG, TURN_LIE_TOLERANCE_DEG, \
    TURN_MIN_FROM_SIGHT_DEG, TURN_NEAR_LIE_DEG
from ghnerf_runtime.estimator import (_FLOOR_BODY_M, _FLOOR_EDGE_FRAC, _NEAR_LIE_STEP_DEG,
                                      _PRIOR_CONFIDENCE_SCALE_M, _PRIOR_FOLLOW_MAX_ERROR_M,
                                      MAX_TIME_STEP_S, STILL_SEVERAL_MIN_JOINTS, PairResult)
from ghnerf_runtime.geometry import triangulate_dlt
from ghnerf_runtime.geometry.camera import REACH_RIM_POINTS, UNDISTORT_POLISH
from ghnerf_runtime.geometry.orbit import AXES_PIVOT_DROP_M, AXES_PIVOT_HOLD_M, PARALLEL_AXES_DEG, PIVOT_CONDITION_DEG
from ghnerf_runtime.geometry.raycast import RASTER_CHUNK
from ghnerf_runtime.geometry.rig import MAX_BASELINE_M, MIN_BASELINE_M
from ghnerf_runtime.geometry.triangulation import CENTRE_TOLERANCE, MIN_BLOCK_VOLUME, MIN_RAY_ANGLE_FLOOR_DEG, \
    MIN_ROW_SHARE
from ghnerf_runtime.novel_view import AUTO_ORBIT_MIN_ANGLE_DEG, HALF_TURN_BAND_DEG
from ghnerf_runtime.onnx_file import STALE_INT8_AGE_S
from ghnerf_runtime.others_scan import SUBJECT_MARGIN_M
from ghnerf_runtime.rig_file import (CAMERA_HEIGHT_RANGE_M, MAX_DISTORTION, MAX_RIG_FILE_BYTES, MAX_SKEW_SHARE,
                                     MAX_VOLUME_FLOOR_GAP_M, MIN_PAIR_ANGLE_DEG, MIN_PERSON_IN_VIEW_SHARE,
                                     PERSON_IN_VIEW_NOTE_SHARE, STANDING_PERSON_M, WIRE_2D_MAX_PX, _PERSON_SAMPLES)
from ghnerf_runtime.skeleton_prior import MIN_CHECK_JOINTS
from ghnerf_runtime.scene_change import (CALM_AFTER_PASSES, CELL_SAMPLES, ONE_VIEW_NOT_VAIN_PAIRS,
                                         RESTLESS_AFTER_WAKES, THUMB_CELLS, WAKE_MIN_CELLS)
from ghnerf_runtime.proxy_matte import BONE_M
from ghnerf_runtime.tracking import COLD_TILE_OVERLAP_M, COLD_TILE_SPLITS
from ghnerf_runtime.two_people import BODY_RADIUS_M, BONE_SLACK_M, MAX_LIMB_M, MIN_APART_M, MIXED_TORSO_SLACK_M, \
    SLACK_DEPTH_BASELINES, TIE_M, TORSO_LIMBS_M, TORSO_TWINS_APART_M, TWIN_SAME_M
from training.data.errors import DatasetError
from training.data.zju import MIN_CAMERA_SPREAD_M, parse_cameras
from training.export.calibration import MIN_FRAMES
from training.export.opsets import MAX_OPSET, MIN_OPSET

REPO = Path(__file__).resolve().parents[1]
RAY = Joints3DConfig().min_ray_angle_deg
DISAGREE = Joints3DConfig().max_prior_disagreement_m
PRIOR_GATE = Joints3DConfig().max_prior_error_m
TRACK_CONF = TrackingConfig().min_confidence
COLD_SHARE = TrackingConfig().cold_tiles_below_share
COLD_REST = TrackingConfig().cold_tiles_rest_every
COLD_WAKE = TrackingConfig().cold_tiles_wake_levels
COLD_MAX_FOOT = TrackingConfig().cold_tiles_max_foot_m
SOLVER_RAY = inspect.signature(triangulate_dlt).parameters["min_ray_angle_deg"].default


def _unit_setting(key: str) -> str:
    """``key``'s value in the shipped unit file, systemd/ghnerf.service."""
    (value,) = re.findall(rf"^{key}=(.*)$", (REPO / "systemd" / "ghnerf.service").read_text(), flags=re.M)
    return value.strip()


def _words(n: int) -> str:
    """``n`` as the docs write a small count in words."""
    return {2: "two", 3: "three", 4: "four", 5: "five", 8: "eight"}.get(n, str(n))


def _exp(value: float) -> str:
    """``value`` as the docs write a power of ten: 1e-9, not Python's 1e-09."""
    return f"{value:g}".replace("e-0", "e-")


def _doc(name: str) -> str:
    # one line per paragraph's worth of text: a phrase may be wrapped anywhere
    return re.sub(r"\s+", " ", (REPO / name).read_text())


@pytest.mark.parametrize(("doc", "phrase"), [
    ("docs/daemon.md", f"gives the queue {CLOSE_DRAIN_S:g} s (`CLOSE_DRAIN_S`"),
    ("docs/protocol.md", f"`CLOSE_DRAIN_S` ({CLOSE_DRAIN_S:g} s)"),
    ("docs/daemon.md", f"fixes the threshold at {MMAP_THRESHOLD / (1 << 20):g} MiB"),
    ("docs/daemon.md", f"tried again for up to {STATE_RETRY_S:g} s (`STATE_RETRY_S`"),
    ("docs/daemon.md", f"looks at the stop every {POLL_S:g} s (`POLL_S`)"),
    ("docs/recording-format.md", f"twice real time; at least {MIN_SPEED:g})"),
    ("docs/protocol.md", f"falls outside {_I16_MIN / _MM_PER_M:.3f} m to {_I16_MAX / _MM_PER_M:.3f} m"),
    ("docs/runtime.md", f"`joints3d.min_ray_angle_deg` ({RAY:g} degrees"),
    ("docs/novel-view.md", f"more than {AUTO_ORBIT_MIN_ANGLE_DEG:g} degrees apart (`AUTO_ORBIT_MIN_ANGLE_DEG`)"),
    ("docs/novel-view.md", f"within {PARALLEL_AXES_DEG:g} degrees (`PARALLEL_AXES_DEG`)"),
    ("docs/novel-view.md", f"k = 1 - cos {PIVOT_CONDITION_DEG:g} degrees, `PIVOT_CONDITION_DEG`"),
    ("docs/novel-view.md", f"within {AXES_PIVOT_HOLD_M:g} m (`AXES_PIVOT_HOLD_M`)"),
    ("docs/novel-view.md", f"from {AXES_PIVOT_DROP_M:g} m (`AXES_PIVOT_DROP_M`)"),
    ("docs/novel-view.md", f"within {HALF_TURN_BAND_DEG:g} degree (`HALF_TURN_BAND_DEG`)"),
    ("docs/geometry.md", f"`joints3d.min_ray_angle_deg` ({RAY:g} deg by default"),
    ("docs/geometry.md", f"The default `min_ray_angle_deg = {SOLVER_RAY:g}`"),
    ("docs/geometry.md", f"`MIN_RAY_ANGLE_FLOOR_DEG` = {_exp(MIN_RAY_ANGLE_FLOOR_DEG)} degrees"),
    ("docs/geometry.md", f"(`CENTRE_TOLERANCE`: centres within {_exp(CENTRE_TOLERANCE)} of their distance"),
    ("docs/geometry.md", f"`MIN_BLOCK_VOLUME` = {_exp(MIN_BLOCK_VOLUME)}, or where"),
    # the largest skew a rig file holds, and the block volume it gives (fx / hypot(fx, s))
    ("docs/geometry.md", f"{MAX_SKEW_SHARE:g} `fx` (`MAX_SKEW_SHARE`), gives {1 / math.hypot(1, MAX_SKEW_SHARE):.3f}"),
    ("docs/rig-file.md", f"at most {MAX_SKEW_SHARE:g} `fx` (`MAX_SKEW_SHARE`;"),
    ("docs/rig-file.md", f"R agree to {_SAME_POSE_TOLERANCE:g} rad (`_SAME_POSE_TOLERANCE`"),
    ("docs/rig-file.md", f"T agree to {_SAME_T_TOLERANCE:g} of the baseline (`_SAME_T_TOLERANCE`"),
    ("docs/rig-file.md", f"{MAX_SKEW_SHARE:g} is axes {90 - math.degrees(math.atan2(1, MAX_SKEW_SHARE)):.1f} degrees off"),
    ("docs/protocol.md", f"`REFUSAL_QUIET_S` ({REFUSAL_QUIET_S:g} s)"),
    ("docs/protocol.md", f"no datagram refused for {REFUSAL_QUIET_S:g} s: a receiver"),
    ("docs/protocol.md", f"`REFUSAL_ANSWER_S` ({REFUSAL_ANSWER_S:g} s)"),
    ("docs/protocol.md", f"about {REFUSAL_QUIET_S + REFUSAL_ANSWER_S:g} s (`REFUSAL_QUIET_S` + `REFUSAL_ANSWER_S`)"),
    ("docs/daemon.md", f"sent {REFUSAL_QUIET_S:g} s or more after the last refusal drew none, judged by a send "
                       f"{REFUSAL_ANSWER_S:g} s or more after it: about {REFUSAL_QUIET_S + REFUSAL_ANSWER_S:g} s after "
                       "a receiver starts"),
    ("docs/geometry.md", f"`MIN_ROW_SHARE` = {_exp(MIN_ROW_SHARE)} of the terms"),
    ("docs/geometry.md", f"`UNDISTORT_POLISH` = {_exp(UNDISTORT_POLISH)}, so"),
    ("docs/geometry.md", f"in {REACH_RIM_POINTS} points (`REACH_RIM_POINTS`)"),
    ("docs/protocol.md", f"at most {LATE_WINDOW} (`LATE_WINDOW`) behind the newest"),
    ("docs/daemon.md", f"at most {LATE_WINDOW} behind the newest (`LATE_WINDOW`)"),
    ("docs/protocol.md", f"once quiet for {QUIET_S:g} s (`QUIET_S`)"),
    ("docs/protocol.md", f"It keeps at most {MAX_PRODUCERS} addresses (`MAX_PRODUCERS`"),
    ("docs/protocol.md", f'`"{SENDER_KEY}": "10.0.0.7:40123"`, with one producer as with several'),
    ("docs/daemon.md", f'`{{"{SENDER_KEY}": "10.0.0.7:40123", "type": "JOINTS", ...}}`'),
    # the STATUS= line's share-out (health._fit_status)
    ("docs/daemon.md", f"The line stays within systemd's {STATUS_MAX} characters"),
    ("docs/daemon.md", f"the state keeps {STATUS_KEEP} characters where they leave it that"),
    ("docs/daemon.md", f"a refused reload then gets the rest (at most {STATUS_RELOAD_MAX} characters, "
                       "`STATUS_RELOAD_MAX`)"),
    ("docs/rig-file.md", f"at most {MAX_DISTORTION:g} in magnitude (`MAX_DISTORTION`"),
    ("docs/rig-file.md", f"files over {MAX_RIG_FILE_BYTES / (1 << 20):g} MiB (`MAX_RIG_FILE_BYTES`"),
    ("docs/rig-file.md", f"under {MIN_PAIR_ANGLE_DEG:g} degree (`MIN_PAIR_ANGLE_DEG`,"),
    # session 65's constants the docs quote: the repeated-view threshold, the handedness check's limit and its
    # clearing point, the capture time's coarsest step
    ("docs/calibration.md", f"within {REPEAT_PX:g} px of the other's, `REPEAT_PX`"),
    ("docs/calibration.md", f"below -{CALIBRATION_MAX_MIRROR:g} (`health.calibration_max_mirror`, "
                            f"{CALIBRATION_MAX_MIRROR:g};"),
    ("docs/calibration.md", f"it clears above -{CALIBRATION_MAX_MIRROR * CLEAR_RATIO:g}."),
    # session 66's: a body lying gives no handedness figure
    ("docs/calibration.md", f"its up axis within {LYING_BAND_DEG:g} degrees of level, `handedness.LYING_BAND_DEG`"),
    ("docs/calibration.md", f"within {LYING_BAND_DEG:g} degrees of level; the rig frame's y is along"),
    # and a left axis from too little of the body's width (side-on) gives none
    ("docs/calibration.md", f"summing under {MIN_LEFT_SPAN_M * 100:g} cm (`handedness.MIN_LEFT_SPAN_M`"),
    # session 67's: a torso wider than one body's (another person's joints mixed in) gives none
    ("docs/calibration.md", f"wider than {MAX_TORSO_SPAN_M * 100:g} cm (`handedness.MAX_TORSO_SPAN_M`"),
    ("docs/runtime.md", f"coarser than {MAX_TIME_STEP_S * 1e3:g} ms at its value (`estimator.MAX_TIME_STEP_S`)"),
    ("docs/rig-file.md", f"outside {CAMERA_HEIGHT_RANGE_M[0]:g}-{CAMERA_HEIGHT_RANGE_M[1]:g} m "
                         "(`CAMERA_HEIGHT_RANGE_M`:"),
    ("docs/rig-file.md", f"more than {MAX_VOLUME_FLOOR_GAP_M:g} m from the floor (`MAX_VOLUME_FLOOR_GAP_M`"),
    ("docs/rig-file.md", f"outside {CAMERA_HEIGHT_RANGE_M[0]:g}-{CAMERA_HEIGHT_RANGE_M[1]:g} m above the floor "
                         "(`CAMERA_HEIGHT_RANGE_M`)"),
    ("docs/protocol.md", f"`facing` (`{FACINGS[0]}`, the default, or `{FACINGS[1]}`)"),
    # session 71: /VMC/Ext/T's frame interval and what a glitched stamp is
    ("docs/protocol.md", f"median of the last {STEPS_KEPT} forward steps"),
    ("docs/protocol.md", f"by more than {JUMP_FRAMES} frame intervals"),
    ("docs/protocol.md", f"stay on the new one for {NEW_TIMELINE_FRAMES} frames"),
    ("docs/protocol.md", f"producer's rate), else 1/{DEFAULT_FPS:g} s, capped"),  # session 72: before the first step
    ("docs/recording-format.md", f"Up to {MENDED_RUN} (`MENDED_RUN`) stamps in a row"),  # session 72
    # the sink options' defaults, as the common query parameters list them
    ("docs/protocol.md", f"`queue` ({SinkOptions.queue}) frames held"),
    ("docs/protocol.md", f"at most {MAX_QUEUE} (`MAX_QUEUE`:"),
    ("docs/protocol.md", f"`status_s` ({SinkOptions.status_s!r}, at least {MIN_STATUS_S:g}, at most {MAX_STATUS_S:g}:"),
    ("docs/protocol.md", f"below {MIN_STATUS_S:g} an idle link"),
    ("docs/protocol.md", f"`send_2d` ({int(SinkOptions.send_2d)});"),
    ("docs/protocol.md", f"`joint_count` ({SinkOptions.joint_count}; more than"),
    # session 51's limits, quoted where the docs describe them
    ("docs/protocol.md", f"of more than {MAX_JOINTS} joints (`MAX_JOINTS`"),
    ("docs/protocol.md", f"`max_fps` extra cap, at least 1/{round(1 / MIN_MAX_FPS)} (a frame an hour)"),
    ("docs/novel-view.md", f"`RASTER_CHUNK` ({RASTER_CHUNK})"),
    # session 52: the crop's follow gate under the skeleton prior
    ("docs/runtime.md", f"its joints expected within {_PRIOR_FOLLOW_MAX_ERROR_M:g} m, or the report gate if looser: "
                        "`_PRIOR_FOLLOW_MAX_ERROR_M`"),
    # session 52: the skeleton prior's disagreement check, its confidence and the weights id
    ("docs/runtime.md", f"default {DISAGREE:g} m; off; session 52"),
    ("docs/runtime.md", f"**{DISAGREE:g} m, no check (default)**"),
    ("docs/runtime.md", f"**{DISAGREE:g}, no check (default)**"),
    ("docs/runtime.md", f"`joints3d.max_prior_disagreement_m` {DISAGREE:g} (off, default)"),
    ("README.md", "`joints3d.max_prior_disagreement_m: 0.25` (off by default:"),
    ("docs/runtime.md", f"at least {MIN_CHECK_JOINTS} of them; `skeleton_prior.disagreement_m`"),
    ("docs/runtime.md", f"fewer than {MIN_CHECK_JOINTS} joints were triangulated"),
    ("docs/runtime.md", f"confidence `exp(-expected error / {_PRIOR_CONFIDENCE_SCALE_M:g} m)` "
                        f"({math.exp(-PRIOR_GATE / _PRIOR_CONFIDENCE_SCALE_M):.2f} to 1 under the default gate"),
    # the follow gate was cut short where exp(-error / scale) fell below tracking.min_confidence
    ("docs/runtime.md", f"the prior's score falls below its default {TRACK_CONF:g} past "
                        f"{-_PRIOR_CONFIDENCE_SCALE_M * math.log(TRACK_CONF):.2f} m"),
    ("docs/runtime.md", f"(`{WEIGHTS_ID_KEY}`, the same in every graph"),
    ("docs/runtime.md", f"`weights_id` (the loaded graphs' shared `{WEIGHTS_ID_KEY}`"),
    ("docs/runtime.md", f"over {STALE_INT8_AGE_S:g} s (`onnx_file.STALE_INT8_AGE_S`"),
    ("docs/training.md", f"carries the same `{WEIGHTS_ID_KEY}` in its metadata"),
    ("docs/training.md", f"with its `{WEIGHTS_ID_KEY}` left out"),
    ("docs/model.md", f"with `{WEIGHTS_ID_KEY}` beside it"),
    ("docs/dataset.md", f"within {100 * MIN_CAMERA_SPREAD_M:g} cm of one another (the runtime's shortest baseline, "
                        "`rig.MIN_BASELINE_M`"),
    ("docs/rig-file.md", f"at most {MAX_BASELINE_M:g} m apart (`MAX_BASELINE_M`"),
    ("docs/calibration.md", f"after {STALL_NOTE_S:g} s without an image pair (`STALL_NOTE_S`)"),
    ("docs/calibration.md", f"outside {USUAL_PITCH_DEG[0]:g} to {USUAL_PITCH_DEG[1]:g} degrees (`USUAL_PITCH_DEG`)"),
    ("docs/rig-file.md", f"outside {USUAL_PITCH_DEG[0]:g} to {USUAL_PITCH_DEG[1]:g} degrees, `USUAL_PITCH_DEG`"),
    ("docs/calibration.md", f"an {COVERAGE_GRID[0]}x{COVERAGE_GRID[1]} grid, `COVERAGE_GRID`"),
    ("docs/calibration.md", f"up to {MISMATCH_TRIES} of them (`MISMATCH_TRIES`)"),
    ("docs/calibration.md", f"than {MIN_VIEWS} names are in both folders"),
    ("docs/model.md", f"fewer than {MIN_FRAMES} frame pairs (`calibration.MIN_FRAMES`"),
    ("docs/model.md", f"fewer than {MIN_FRAMES}, `calibration.MIN_FRAMES` as for"),
    ("docs/model.md", f"`python -m training.export --opset` takes {MIN_OPSET} to {MAX_OPSET}"),
    # session 53: a sink whose receiver stopped reading reads stalled; resolve_s has a floor
    ("docs/protocol.md", f"`stall_s` ({SinkOptions.stall_s!r}, at least {MIN_STALL_S:g}, at most {MAX_STALL_S:g}):"),
    ("docs/protocol.md", f"(below {MIN_STALL_S:g} one late write would read as a stall)"),
    ("docs/daemon.md", f"the sink's `stall_s`, {SinkOptions.stall_s:g} s by default"),
    ("docs/protocol.md", f"at least every {MIN_RESOLVE_S:g} s (`MIN_RESOLVE_S`"),
    ("docs/protocol.md", f"`resolve_s` ({RESOLVE_S:g}, at least {MIN_RESOLVE_S:g});"),
    ("docs/daemon.md", f"every `resolve_s` ({RESOLVE_S:g}, at least {MIN_RESOLVE_S:g}) seconds"),
    # session 53: the farthest box a float32 near/far is made of
    ("docs/model.md", f"for a box reaching farther than {MAX_DEPTH_M:g} m (`MAX_DEPTH_M`)"),
    ("docs/runtime.md", f"farther than {MAX_DEPTH_M / 1000:g} km (`contract.MAX_DEPTH_M`)"),
    # session 53: the daemon's calibration check, its defaults quoted where it is explained
    ("docs/calibration.md", f"the last `health.calibration_window` ({CALIBRATION_WINDOW}) measured pairs"),
    ("docs/calibration.md", f"above `health.calibration_max_px` ({CALIBRATION_MAX_PX:g} px)"),
    ("docs/calibration.md", f"the {CALIBRATION_MAX_PX:g} px limit is"),
    ("docs/calibration.md", f"under {'three quarters' if CLEAR_RATIO == 0.75 else CLEAR_RATIO} of the limit"),
    ("docs/daemon.md", f"under {'three quarters' if CLEAR_RATIO == 0.75 else CLEAR_RATIO} of it (`CLEAR_RATIO`)"),
    # session 54: the floor check's default, quoted where it is explained and in the config table
    ("docs/calibration.md", f"`health.calibration_max_floor_m` ({CALIBRATION_MAX_FLOOR_M:g} m)"),
    ("docs/daemon.md", f"| `health.calibration_max_floor_m` | {CALIBRATION_MAX_FLOOR_M:g} |"),
    # session 72: the daemon's config file cap
    ("docs/daemon.md", f"A file over {MAX_CONFIG_FILE_BYTES >> 20} MiB (`MAX_CONFIG_FILE_BYTES`"),
    # session 57: the floor check's standing foot (a setting since), its default, range and --measure-floor's pairs
    ("docs/calibration.md", f"`estimator.joints3d.foot_standing_m` ({FOOT_STANDING_M:g} m by default"),
    ("docs/daemon.md", f"`estimator.joints3d.foot_standing_m` ({FOOT_STANDING_M:g} m, bare feet)"),
    ("docs/runtime.md", f"less `joints3d.foot_standing_m` ({FOOT_STANDING_M:g} m by default"),
    ("docs/calibration.md", f"outside 0 to {MAX_FOOT_STANDING_M:g} m (the setting's range"),
    ("docs/calibration.md", f"runs pairs until {DEFAULT_PAIRS} of them (`--measure-floor PAIRS`)"),
    ("docs/calibration.md", f"fewer than PAIRS of {dict([(5, 'five')]).get(READS_PER_PAIR)} times as many"),
    ("docs/daemon.md", f"until PAIRS ({DEFAULT_PAIRS}) of them"),
    # session 58: the opens in a row that stop the daemon on frames of another size than the rig file's
    ("docs/daemon.md", f"the same size on `SIZE_MISMATCH_OPENS` ({SIZE_MISMATCH_OPENS}) opens"),
    ("docs/daemon.md", f"(the same on {SIZE_MISMATCH_OPENS} opens in a row"),
    ("docs/daemon.md", f"before any pair on `SIZE_MISMATCH_OPENS` ({SIZE_MISMATCH_OPENS}) opens in a row, as the "
                       f"daemon"),
    ("docs/daemon.md", f"then \"(on {SIZE_MISMATCH_OPENS} opens in a row, ...)\""),
    # session 58's docs review: the same count in words where README.md and the daemon's step 2 say it
    ("docs/daemon.md", f"size than the rig file's on {'three' if SIZE_MISMATCH_OPENS == 3 else SIZE_MISMATCH_OPENS} "
                       "opens in a row before they ever delivered its size"),
    ("README.md", f"on {'three' if SIZE_MISMATCH_OPENS == 3 else SIZE_MISMATCH_OPENS} opens in a row before they "
                  "ever delivered its size"),
    # session 59: a replay:// take whose images are not its rig's size, refused at open like those cameras
    ("docs/recording-format.md", f"stops after {'three' if SIZE_MISMATCH_OPENS == 3 else SIZE_MISMATCH_OPENS} opens "
                                 "(exit 2)"),
    # session 58: the torso of two people (ghnerf_runtime/two_people.py; since session 59 in docs/two-people.md) and
    # the kept turn's rolls (estimator.py; since session 59 in docs/turn-search.md, as the turn search's other
    # constants below)
    ("docs/two-people.md", f"`TORSO_LIMBS_M` ({' and '.join(f'{v:g}' for v in sorted(set(TORSO_LIMBS_M.values()), reverse=True))}"
                           f" m, `proxy_matte.BONE_M`'s generous adult) by more than `MIXED_TORSO_SLACK_M` "
                           f"({MIXED_TORSO_SLACK_M:g} m)"),
    ("docs/two-people.md", f"Past {SLACK_DEPTH_BASELINES:g} baselines from the cameras, the limb's part along the line"),
    ("docs/two-people.md", f"`SLACK_DEPTH_BASELINES` ({SLACK_DEPTH_BASELINES:g}) baselines"),
    # session 60: one peak read as both sides' joints (two_people.one_side_each)
    ("docs/two-people.md", f"`two_people.TWIN_SAME_M` ({TWIN_SAME_M:g} m)"),
    # session 60's review: the split's shoulder held the torso's width from its found twin (two_people.held_apart)
    ("docs/two-people.md", f"the two bones (`proxy_matte.BONE_M`, {BONE_M['LShoulder']:.2f} m each) less `BONE_SLACK_M` "
                           f"({BONE_SLACK_M:g} m) for the ends' error, as `one_skeleton` allows it: "
                           f"{TORSO_TWINS_APART_M[(JOINT_NAMES.index('LShoulder'), JOINT_NAMES.index('RShoulder'))]:g} "
                           f"m for the shoulders"),
    ("docs/two-people.md", f"The hips' bound (2 x {BONE_M['LHip']:g} - {BONE_SLACK_M:g} m = "
                           f"{2 * BONE_M['LHip'] - BONE_SLACK_M:.2f} m) is below zero, so hips are not checked"),
    ("docs/turn-search.md", f"at most {KEPT_TURN_STEP_DEG:g} degrees from that pass's (`KEPT_TURN_STEP_DEG`)"),
    ("docs/turn-search.md", f"within {KEPT_TURN_SECTOR_DEG:g} degrees of the turn (`KEPT_TURN_SECTOR_DEG`"),
    # session 57's rule for a search's turned pass (ghnerf_runtime/body_lie.py), quoted since session 59
    ("docs/turn-search.md", f"upside down within {TURN_LIE_TOLERANCE_DEG:g} degrees (`TURN_LIE_TOLERANCE_DEG`;"),
    # the wait after a failed turn search, which an early search (session 59) runs on from
    ("docs/turn-search.md", f"`roi.turn_search_every` - 1 ({RoiConfig().turn_search_every - 1}) weak pairs that do not "
                            "search"),
    ("docs/turn-search.md", f"least {TURN_MIN_FROM_SIGHT_DEG:g} degrees (`TURN_MIN_FROM_SIGHT_DEG`) from each camera's"),
    # session 60: a failed search's refused turned pass nearly lying lets the next weak pair search
    ("docs/turn-search.md", f"at most `TURN_NEAR_LIE_DEG` ({TURN_NEAR_LIE_DEG:g}) degrees short of level (60-70 "
                            "degrees from upright"),
    ("docs/turn-search.md", f"at least `_NEAR_LIE_STEP_DEG` ({_NEAR_LIE_STEP_DEG:g}) degrees nearer the window"),
    ("docs/rig-file.md", f"runtime may add ({MAX_NEAR_FAR_MARGIN_M:g} m, `contract.MAX_NEAR_FAR_MARGIN_M`"),
    ("docs/rig-file.md", f"within {MAX_DEPTH_M:g} m (`contract.MAX_DEPTH_M`) of every camera"),
    # session 59's review: docs/bring-up.md, the checklist a user follows on hardware nobody here could try
    ("docs/bring-up.md", f"under {100 * SLOW_SHARE:g} % of `fps`"),
    ("docs/bring-up.md", f"`width` and `height` ({DepthaiOptions().width}x{DepthaiOptions().height} by default)"),
    ("docs/bring-up.md", f"({DepthaiOptions().width}x{DepthaiOptions().height} when `depthai://` names none)"),
    ("docs/bring-up.md", f"`mount_height` metres above the floor ({DEFAULT_MOUNT_HEIGHT_M:.1f} when not given"),
    ("docs/bring-up.md", f"It measures {DEFAULT_PAIRS} pairs by default (`--measure-floor PAIRS`"),
    ("docs/bring-up.md", f"the model failing on {MAX_FAILED_RUNS} pairs in a row"),
    ("docs/bring-up.md", f"cameras never delivered the rig file's size, {_words(SIZE_MISMATCH_OPENS)} opens in a row"),
    ("docs/bring-up.md", "a path under " + ", ".join(f"`{f}`" for f in (HOME_FOLDERS + PRIVATE_TMP_FOLDERS)[:-1])
                         + f" or `{PRIVATE_TMP_FOLDERS[-1]}` means"),
    ("docs/bring-up.md", f"Expect `Type={_unit_setting('Type')}`, `WatchdogUSec={_unit_setting('WatchdogSec')}s`"),
    ("docs/calibration.md", f"shows {PATTERN_CHECK_MARKERS} or more (`PATTERN_CHECK_MARKERS`)"),
    # session 53: a udp:// or vmc:// host no lookup can answer is refused when the URL is read
    ("docs/protocol.md", f"a name past {MAX_HOST_NAME} characters), named when the sink opens"),
    # session 54: the board, consensus and check constants docs/calibration.md explains
    ("docs/calibration.md", f"The default board is {BoardSpec().squares_x}x{BoardSpec().squares_y} squares of "
                            f"{1000 * BoardSpec().square_m:g} mm"),
    ("docs/calibration.md", f"at least {MIN_CORNERS}, and not all but one on one line"),
    # session 68: ghcal synth's rig and board, quoted beside the default board's
    ("docs/calibration.md", f"0.6 m apart at {SYNTH_CAMERA_HEIGHT_M:g} m, pitched {SYNTH_PITCH_DEG:g} degrees down and "
                            "converging"),
    ("docs/calibration.md", f"whole in both views from {SYNTH_VOLUME_NEAR_M:g} m ahead, where its working volume starts"),
    ("docs/calibration.md", f"a board of {SYNTH_BOARD.squares_x}x{SYNTH_BOARD.squares_y} squares of "
                            f"{1000 * SYNTH_BOARD.square_m:g} mm (`calibration.render.SYNTH_BOARD`"),
    ("docs/rig-file.md", f"the rig's volume starts {SYNTH_VOLUME_NEAR_M:g} m ahead (`SYNTH_VOLUME_NEAR_M`;"),
    ("docs/rig-file.md", f"raised to {SYNTH_CAMERA_HEIGHT_M:g} m and pitched {SYNTH_PITCH_DEG:g} degrees down"),
    ("docs/calibration.md", f"agree within {CONSENSUS_MM:g} mm and {CONSENSUS_DEG:g} degrees "
                            "(`CONSENSUS_MM`, `CONSENSUS_DEG`)"),
    ("docs/calibration.md", f"`--max-px` (default {CheckLimits.max_px:g} px rms)"),
    ("docs/calibration.md", f"`--max-scale-error` (default {100 * CheckLimits.max_scale_error:g} %)"),
    ("docs/calibration.md", f"`--max-floor-mm` off the floor (default {CheckLimits.max_floor_mm:g} mm)"),
    # session 54: two people without a track, separated and one picked (ghnerf_runtime/two_people.py; docs/two-people.md)
    ("docs/two-people.md", f"further than {BODY_RADIUS_M:g} m from a centre costs as much as none"),
    ("docs/two-people.md", f"two centres nearer than {MIN_APART_M:g} m are one column counted twice"),
    ("docs/two-people.md", f"nearer, within {MAX_LIMB_M:g} m: a waving hand"),
    ("docs/two-people.md", f"within a limb's length ({MAX_LIMB_M:g} m)"),
    ("docs/two-people.md", f"within {TIE_M:g} m of each other, the one nearer the cameras |"),
    ("docs/two-people.md", f"`nearest` | the one nearest the cameras (the floor point below their midpoint); within "
                           f"{TIE_M:g} m, the one nearer the centre line |"),
    ("docs/two-people.md", f"hence the {TIE_M:g} m within which two distances count as equal"),
    ("docs/two-people.md", f"stay flagged while at least "
                           f"{'one' if STILL_SEVERAL_MIN_JOINTS == 1 else STILL_SEVERAL_MIN_JOINTS} joint shows twice"),
    # session 54: the smoothing's lowest cutoff and the floor check's frame-edge margin (estimator._FLOOR_EDGE_FRAC)
    ("docs/runtime.md", f"{MIN_CUTOFF_HZ:g} Hz at least (`config.MIN_CUTOFF_HZ`, a time constant of "
                        f"{1 / (2 * math.pi * MIN_CUTOFF_HZ):.0f} s"),
    ("docs/runtime.md", f"shown by both frames at least {'a fifth' if _FLOOR_EDGE_FRAC == 0.2 else _FLOOR_EDGE_FRAC} "
                        "of the crop window's side inside their edges"),
    ("docs/calibration.md", f"both frames show it at least {'a fifth' if _FLOOR_EDGE_FRAC == 0.2 else _FLOOR_EDGE_FRAC}"
                            " of the crop's side inside their edges"),
    # session 56: the floor check's feet near the person's own body, in place of the box gates (estimator._FLOOR_BODY_M)
    ("docs/calibration.md", f"within {_FLOOR_BODY_M:g} m across the floor (x, z) of the"),
    ("docs/runtime.md", f"within {_FLOOR_BODY_M:g} m across the floor of the median of the person's triangulated "
                        "joints"),
    # session 66: the cold tiles (tracking.cold_tiles_below_share, tracking.volume_tiles; a 128-pixel model input)
    ("docs/runtime.md", f"`tracking.cold_tiles_below_share` ({COLD_SHARE:g}: {COLD_SHARE * 128:.0f} of 128 model "
                        "pixels)"),
    ("docs/runtime.md", f"Rigs whose cold crop frames that person at {COLD_SHARE:g} or more have no tiles"),
    ("docs/runtime.md", f"cuts the volume into {_words(COLD_TILE_SPLITS[0] * COLD_TILE_SPLITS[1])} tiles"),
    ("docs/runtime.md", f"`COLD_TILE_SPLITS`, each grown `COLD_TILE_OVERLAP_M` = {COLD_TILE_OVERLAP_M:g} m into"),
    ("docs/rig-file.md", f"under {COLD_SHARE * 128:.0f} model pixels ({COLD_SHARE:g} of the crop, the tiles' bound)"),
    ("docs/runtime.md", f"(`tracking.cold_tiles_rest_every`, default {COLD_REST}, session 66)"),
    ("docs/runtime.md", f'"cold_tiles_rest_every": {COLD_REST}, "cold_tiles_wake_levels": {COLD_WAKE!r}, '
                        f'"cold_tiles_max_foot_m": {COLD_MAX_FOOT!r}}}'),
    # session 72: the floating-foot bound of tile finds, a config field
    ("docs/runtime.md", f"over {COLD_MAX_FOOT:g} m above the floor is refused and its track dropped "
                        f"(`tracking.cold_tiles_max_foot_m`, {COLD_MAX_FOOT:g} m,"),
    # session 67: the resting search's wake-up (tracking.cold_tiles_wake_levels; scene_change's copy and its cells)
    ("docs/runtime.md", f"(`tracking.cold_tiles_wake_levels`, default {COLD_WAKE:g}, session 67)"),
    ("docs/runtime.md", f"{THUMB_CELLS[0]} x {THUMB_CELLS[1]} cells, each the mean of {CELL_SAMPLES ** 2} pixels"),
    ("docs/runtime.md", f"in {_words(WAKE_MIN_CELLS)} cells or more by over `cold_tiles_wake_levels`"),
    # session 68: a cell that keeps waking the rest in vain wakes it no more (a screen playing)
    ("docs/runtime.md", f"`scene_change.RESTLESS_AFTER_WAKES` ({_words(RESTLESS_AFTER_WAKES)}) such searches in vain"),
    ("docs/runtime.md", f"`scene_change.CALM_AFTER_PASSES` ({_words(CALM_AFTER_PASSES)}) tile passes in a row"),
    # session 71: a person one camera alone sees over a round's pairs clears the wake
    ("docs/runtime.md", f"`scene_change.ONE_VIEW_NOT_VAIN_PAIRS` ({_words(ONE_VIEW_NOT_VAIN_PAIRS)}) pairs in a "
                        "row clears the wake"),
    ("docs/runtime.md", f"unless one camera sees them over {_words(ONE_VIEW_NOT_VAIN_PAIRS)} pairs in a row"),
    ("docs/runtime.md", f"a new picture of {SCREEN_BLOCKS[0]} x {SCREEN_BLOCKS[1]} coloured blocks every pair"),
    ("docs/runtime.md", f"| docs/examples/rig.json | tiles, rest every {COLD_REST} (default) |"),
    # session 66: why the scan tells nobody behind the subject (the blanked box, the benchmark's own-peak radius)
    ("docs/two-people.md", f"the reported joints' box grown {SUBJECT_MARGIN_M:g} m every way "
                           "(`others_scan.SUBJECT_MARGIN_M`"),
    ("docs/two-people.md", f"the subject's box grown {SUBJECT_MARGIN_M:g} m covers every one of their joints"),
    ("docs/two-people.md", f"within {OWN_PEAK_CELLS:g} cells of their joint and not within {OWN_PEAK_CELLS:g} of the"),
    ("docs/two-people.md", f"peak farther than {OWN_PEAK_CELLS:g} cells from that person's joint"),
    # session 66: the framing warning (a standing person at the volume's centre who does not fit the view)
    ("docs/rig-file.md", f"warns where a {STANDING_PERSON_M:g} m person (`STANDING_PERSON_M`)"),
    ("docs/rig-file.md", f"shows under {MIN_PERSON_IN_VIEW_SHARE * 100:g} % of their height"),
    ("docs/rig-file.md", f"`rig_file.person_in_view_share`: {_PERSON_SAMPLES} points from the feet"),
    # session 67: the framing note (INFO) for the band the warning spares
    ("docs/rig-file.md", f"under {PERSON_IN_VIEW_NOTE_SHARE * 100:g} % of their height (`PERSON_IN_VIEW_NOTE_SHARE`"),
    # session 67: the joint stream's 2D range (i16 quarter pixels) warned of at load
    ("docs/rig-file.md", f"a coordinate past {WIRE_2D_MAX_PX:g} px (`WIRE_2D_MAX_PX`, 32767 / 4)"),
    ("docs/protocol.md", f"a coordinate past {WIRE_2D_MAX_PX:g} px does not fit in i16"),
])
def test_the_docs_quote_the_constants(doc, phrase):
    assert phrase in _doc(doc), f"{doc} does not say {phrase!r}: the code's value changed, or the doc's wording"


def test_the_daemon_doc_names_every_file_in_a_rig_url():
    """docs/daemon.md, "Paths": every part of a rig URL that ``drivers.url_paths`` reads from the config file's
    folder, and every plain path key, is named there (a backend given a file option is listed with it)."""
    text = _doc("docs/daemon.md")
    paths = text.split("**Paths.**", 1)[1].split("```", 1)[0]
    for scheme, parts in FILE_PARTS.items():
        assert f"`{scheme}://" in paths, scheme
        for option in parts.options:
            assert f"`{option}=" in paths, f"{scheme}://?{option}= is read from the config's folder; say so"
    for key in DAEMON_PATH_KEYS:
        assert f"`{'.'.join(key)}`" in paths, key


def test_hello_and_status_seq_before_the_first_frame_is_said_alike_in_every_doc():
    """HELLO/STATUS carry 2**32 - 1 before the first frame (``NO_FRAME_SEQ``); the protocol doc, the C decoder's
    doc and its header say so in their own words, which must stay with the constant."""
    assert NO_FRAME_SEQ == 2**32 - 1  # the docs write it 2³² − 1
    assert "before the producer's first frame, 2³² − 1" in _doc("docs/protocol.md")
    assert f"2³² − 1 (`0x{NO_FRAME_SEQ:08X}`) before the sender's first" in _doc("docs/c-decoder.md")
    assert f"0x{NO_FRAME_SEQ:08X} before the first" in _doc("clients/c/ghjoints.h")
    assert "HELLO, STATUS: the last frame's, 2³² − 1 before the first" in _doc("docs/protocol.md")  # the header


def test_the_model_doc_quotes_the_card_s_int8_parity():
    """docs/model.md quotes the worst int8-vs-fp32 figures of ``parity`` in models/model_card.json (the held-out
    scene ``make model`` checks); a new model card must bring the doc along."""
    parity = json.loads((REPO / "models/model_card.json").read_text())["parity"]
    graphs = [parity[variant]["graphs"] for variant in parity]
    rgb = max(g["render_rgb"]["rgb"]["max_abs"] for g in graphs)
    depth_cm = 100 * max(g["render_rgb"]["depth"]["mean_abs"] for g in graphs)
    heat = max(g["query"]["joint_heat"]["max_abs"] for g in graphs)
    density = max(g["query"]["density"]["mean_abs"] for g in graphs)
    phrase = f"gives at most {rgb:.3f}, {depth_cm:.1f} cm, {heat:.2f} and {density:.3f}"
    assert phrase in _doc("docs/model.md"), phrase


def test_the_zju_unit_check_is_the_runtime_s_shortest_baseline():
    """docs/dataset.md says the ZJU loader's metres-or-millimetres threshold is ``rig.MIN_BASELINE_M``."""
    assert MIN_CAMERA_SPREAD_M == MIN_BASELINE_M


def test_the_dataset_doc_quotes_the_zju_distortion_error_as_the_loader_words_it():
    """docs/dataset.md quotes the message of a camera whose ``D`` has a count OpenCV does not take."""
    K, R, T = [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [[1.0, 0, 0], [0, 1, 0], [0, 0, 1]], [[0.0], [0.0], [0.0]]
    annots = {"cams": {"K": [K] * 3, "R": [R] * 3, "T": [T, [[100.0], [0.0], [0.0]], [[0.0], [100.0], [0.0]]],
                       "D": [[[0.0]] * 5, [[0.0]] * 5, [[0.0]] * 3]}}
    with pytest.raises(DatasetError) as e:
        parse_cameras(annots, Path("annots.npy"))
    said = str(e.value).split("annots.npy: ", 1)[-1]
    assert said.startswith("cams.D[2] must hold ")
    assert f"`{said}`" in _doc("docs/dataset.md"), said


def test_the_readme_quotes_what_a_rig_url_s_leading_zero_is_told():
    """README, "Rig URLs": a leading zero is refused saying what to write (``drivers.url.whole_number``)."""
    with pytest.raises(ValueError, match=r"\(write 10;") as e:
        whole_number("010")
    assert "saying what to write (`write 10`)" in _doc("README.md"), str(e.value)


def test_the_runtime_doc_names_every_key_of_a_pair_s_json():
    """docs/runtime.md, "Output": every top-level key ``PairResult.to_json`` writes is named there (quoted in the
    example or in backticks), so a key added to the JSON (``prior_fallback``, session 52) is documented."""
    n = len(JOINT_NAMES)
    result = PairResult(0, JOINT_NAMES, np.zeros((n, 3)), np.zeros(n, np.float32), np.ones(n, bool),
                        {"left": np.zeros((n, 2))}, {"left": np.zeros(n)}, {"left": np.ones(n, bool)},
                        {"total": 1.0}, False, {"left": True}, {}, "triangulate")
    text = (REPO / "docs/runtime.md").read_text()
    output = text.split("**Output**: one object per frame pair", 1)[1].split("\n## ", 1)[0]
    unnamed = [k for k in result.to_json() if f'"{k}"' not in output and f"`{k}`" not in output]
    assert not unnamed, f"docs/runtime.md, Output, does not name {unnamed}"


def _code_paragraph(page: str) -> str:
    """A feature page's ``Code: ...`` paragraph, which names the files, methods and functions the feature lives in
    (since session 61 a Contents list and "Today, in brief" come before it, so it is found by its lead)."""
    return "Code: " + page.split("\nCode: ", 1)[1].split("\n\n", 1)[0]


def test_the_turn_search_page_names_its_keys_and_the_code_it_points_at():
    """docs/turn-search.md (the crop turn search's page, split from docs/runtime.md in session 59) is where
    ``roi.turn_search``'s readers are sent: it names every ``roi.turn_search*`` key, and the files, estimator
    methods and ``body_lie`` functions its Code paragraph points at exist (a rename would leave it pointing at
    nothing)."""
    import dataclasses

    from ghnerf_runtime import body_lie
    from ghnerf_runtime.estimator import Estimator

    page = (REPO / "docs/turn-search.md").read_text(encoding="utf-8")
    keys = [f.name for f in dataclasses.fields(RoiConfig) if f.name.startswith("turn_search")]
    assert len(keys) >= 3, keys  # turn_search, turn_search_below, turn_search_every at least
    unnamed = [k for k in keys if f"`roi.{k}`" not in page]
    assert not unnamed, f"docs/turn-search.md does not name {unnamed}"
    code = _code_paragraph(page)
    files = re.findall(r"\b((?:ghnerf_runtime|benchmarks|tests)/[\w/]+\.py)\b", code)
    methods = re.findall(r"`(?:Estimator\.)?(_\w+)`", code)
    functions = re.findall(r"`(lies_as_\w+|nears_a_\w+)`", code)
    assert len(files) >= 5 and len(methods) >= 3 and len(functions) >= 3, (files, methods, functions)
    missing = [f for f in files if not (REPO / f).is_file()]
    missing += [f"Estimator.{m}" for m in methods if not hasattr(Estimator, m)]
    missing += [f"body_lie.{f}" for f in functions if not hasattr(body_lie, f)]
    assert not missing, f"docs/turn-search.md's Code paragraph points at what is not there: {missing}"


#: The estimator keys of two people in view (``Joints3DConfig``), named on docs/two-people.md.
TWO_PEOPLE_KEYS = ("second_person_ratio", "second_person_min_joints", "behind_min_joints", "max_track_step_m",
                   "pick_subject")


def test_the_two_people_page_names_its_keys_and_the_code_it_points_at():
    """docs/two-people.md (two people in view, split from docs/runtime.md in session 59) is where
    ``several_people``'s readers are sent: it names the two-people ``joints3d`` keys and every ``pick_subject``
    rule, and the files, estimator and subject selector methods and ``two_people`` functions its Code paragraph
    points at exist (a rename would leave it pointing at nothing; session 60 moved the subject selection to
    ``ghnerf_runtime/subject.py``)."""
    import dataclasses

    from ghnerf_runtime import subject, two_people
    from ghnerf_runtime.config import PICK_SUBJECT_RULES
    from ghnerf_runtime.estimator import Estimator

    page = (REPO / "docs/two-people.md").read_text(encoding="utf-8")
    fields = {f.name for f in dataclasses.fields(Joints3DConfig)}
    assert set(TWO_PEOPLE_KEYS) <= fields, set(TWO_PEOPLE_KEYS) - fields
    unnamed = [k for k in TWO_PEOPLE_KEYS if f"`joints3d.{k}`" not in page]
    unnamed += [f"pick_subject {r}" for r in PICK_SUBJECT_RULES if f"`{r}`" not in page]
    assert not unnamed, f"docs/two-people.md does not name {unnamed}"
    code = _code_paragraph(page)
    files = re.findall(r"\b((?:ghnerf_runtime|benchmarks|tests)/[\w/]+\.py)\b", code)
    # each file's names: those in the parentheses after it, before the next file's (two_people, subject, estimator)
    named = code.split("`ghnerf_runtime/two_people.py` (", 1)[-1].split("`ghnerf_runtime/subject.py`", 1)[0]
    functions = re.findall(r"`(\w+)`", named)
    selected = code.split("`ghnerf_runtime/subject.py` (", 1)[-1].split("`ghnerf_runtime/estimator.py`", 1)[0]
    selector = re.findall(r"`(?:SubjectSelector\.)?([a-z_]\w*)`", selected)
    methods = re.findall(r"`(?:Estimator\.)?(_\w+)`", code.split("`ghnerf_runtime/estimator.py` (", 1)[-1])
    assert len(files) >= 6 and len(functions) >= 5 and len(selector) >= 8 and len(methods) >= 2, \
        (files, functions, selector, methods)
    missing = [f for f in files if not (REPO / f).is_file()]
    missing += [f"two_people.{f}" for f in functions if not hasattr(two_people, f)]
    missing += [f"subject.{m}" for m in selector if not hasattr(subject.SubjectSelector, m) and not hasattr(subject, m)]
    missing += [f"Estimator.{m}" for m in methods if not hasattr(Estimator, m)]
    assert not missing, f"docs/two-people.md's Code paragraph points at what is not there: {missing}"
