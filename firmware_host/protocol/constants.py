"""Wire constants of the joint-stream protocol (docs/protocol.md is the spec)."""
from __future__ import annotations

import enum
import struct

PROTOCOL_VERSION = 1

# Header: version u8, msg_type u8, flags u8, seq u32, capture_us u64, send_us u64.
HEADER = struct.Struct("<BBBIQQ")
HEADER_LEN = HEADER.size  # 23
CRC_LEN = 2
MIN_PACKET_LEN = HEADER_LEN + CRC_LEN

# Bounds that let a microcontroller decode with fixed buffers.
MAX_PACKET_LEN = 512  # decoded packet, header + payload + CRC
MAX_FRAME_LEN = 515  # COBS-encoded bytes between two delimiters
MAX_JOINTS = 64
MAX_RIG_ID_LEN = 32
MAX_CAMERAS = 8
MAX_CAMERA_NAME_LEN = 16

U32_MAX = 0xFFFF_FFFF
#: The seq HELLO and STATUS carry before the sender's first frame: the one before 0, as they carry the last
#: frame's seq and the next JOINTS carries that plus one (docs/protocol.md section 3). 0 there read as "frame 0
#: sent"; a receiver reads this one as a sender that (re)started.
NO_FRAME_SEQ = U32_MAX
U64_MAX = 0xFFFF_FFFF_FFFF_FFFF


class MsgType(enum.IntEnum):
    HELLO = 0x01
    STATUS = 0x02
    JOINTS = 0x10
    JOINTS_2D = 0x11


class Flags(enum.IntFlag):
    NONE = 0
    # The sender is deliberately skipping frames to stay within the link's capacity.
    DECIMATED = 0x01
    # The sender dropped at least one frame (queue overflow or failed write)
    # since the previous JOINTS packet on this link.
    DROPPED = 0x02
    # Bits 2-6 say what the estimate is (set on the frame's JOINTS and JOINTS_2D; docs/protocol.md section 3).
    # Header bits, not appended payload bytes: they cost no link budget, and decoders of before session 53
    # already pass unknown bits through ("ignore when reading").
    # Two people in view: the joints are one person's only, the tracked subject's or, without a track, the one
    # joints3d.pick_subject picks (all missing with pick_subject "none", the rule before session 54).
    SEVERAL_PEOPLE = 0x04
    # The skeleton prior disagreed with the triangulation, which was sent instead.
    PRIOR_FALLBACK = 0x08
    # One camera alone saw the person: no 3D (every JOINTS joint missing), only that camera's JOINTS_2D.
    SINGLE_VIEW = 0x10
    # The daemon's calibration check finds the views no longer agree or the feet have left the floor (a camera
    # moved since calibration): 3D may be off. Also set in the STATUS header while it lasts, so it reaches a
    # receiver while no frame flows.
    CALIBRATION_SUSPECT = 0x20
    # The estimator's latest scan of the whole working volume (presence.scan_every_s, off by default) showed someone
    # besides the tracked subject in both views; held from one scan to the next. Only from a sender whose HELLO
    # announces it (ALL_SCENE_FLAGS): without the scan a frame lacks it whoever is near.
    SOMEONE_ELSE = 0x40


#: The scene flags every sender since session 53 sets and announces in its HELLO's header ``flags`` (this value);
#: an older sender's HELLO has 0, so a receiver can tell "no second person" from "a sender too old to say".
#: Kept at 0x3C when SOMEONE_ELSE came (session 65): a receiver that checks a HELLO for this whole mask still
#: finds it in a sender that does not scan.
SCENE_FLAGS = int(Flags.SEVERAL_PEOPLE | Flags.PRIOR_FALLBACK | Flags.SINGLE_VIEW | Flags.CALIBRATION_SUSPECT)
#: Every flag that describes a frame's estimate (``JointFrame.scene_flags``), as opposed to the sender's link: the
#: HELLO mask of a sender that runs the estimator's scan for others (:func:`hello_scene_flags`).
ALL_SCENE_FLAGS = SCENE_FLAGS | int(Flags.SOMEONE_ELSE)


def hello_scene_flags(scans_for_others: bool) -> int:
    """The header ``flags`` of a HELLO: the scene flags its sender sets, SOMEONE_ELSE only where the estimator scans
    for others, so a receiver can tell "nobody else seen" from "nobody looked"."""
    return ALL_SCENE_FLAGS if scans_for_others else SCENE_FLAGS


class JointSet(enum.IntEnum):
    BODY_25 = 0


class Units(enum.IntEnum):
    MILLIMETRES = 0


class CoordFrame(enum.IntEnum):
    # x right, y down, z forward (away from the cameras), origin from the rig file.
    RIG = 0


class Fault(enum.IntEnum):
    OK = 0
    RATE_LIMITED = 1  # link cannot carry the requested rate; decimating
    QUEUE_OVERFLOW = 2  # frames dropped because the link fell behind
    LINK_ERRORS = 3  # writes failed or the link reconnected
    ESTIMATOR_STALLED = 4  # set by the daemon
    CAMERA_FAULT = 5  # set by the daemon


# Per-joint wire sizes.
JOINT3D_BYTES = 7  # int16 x, y, z (mm) + u8 confidence
JOINT2D_BYTES = 5  # int16 u, v (quarter pixels) + u8 confidence
UV_SCALE = 4  # 2D coordinates are sent in 1/4 pixel

# Decoder event codes, in the order the checks are made.
ERROR_CODES = ("oversize", "cobs", "short", "crc", "version", "malformed")


def mask_len(count: int) -> int:
    """Bytes of the missing-joint bit mask for ``count`` joints."""
    return (count + 7) // 8
