"""The words the frame check (:func:`ghnerf_runtime.estimator.check_crop`) gives a rejected crop.

One place for them: ``PairResult.frame_reason``, its JSON and the daemon's status file
(``rig.frames_rejected``) all use these words, and a reader may match on them. Kept out of the
estimator so the daemon's health report can name them without importing cv2 and the model code.
"""
from __future__ import annotations

__all__ = ["FLAT", "NOISE", "NON_FINITE", "REASONS"]

#: Standard deviation under ``frame_check.min_std`` 8-bit levels: black, saturated, a covered lens,
#: or a crop that shows none of the frame. (The check measures contrast only, not brightness: a black
#: and a white crop are both "flat".)
FLAT = "flat"
#: More than ``frame_check.max_noise_ratio`` of the variance is pixel-to-pixel detail, and more than
#: ``frame_check.max_coarse_noise_ratio`` of its 2x2 block means' is too (a stream of garbage; a very dark room at
#: very high gain, docs/runtime.md "Frame check").
NOISE = "noise"
#: NaN or infinity in the model input.
NON_FINITE = "non-finite"
#: Every reason, in the order the check tests them (non-finite first).
REASONS = (NON_FINITE, FLAT, NOISE)
