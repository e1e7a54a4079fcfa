"""BVH motion files: parse, write and forward kinematics (no retargeting; see retarget.py).

Supported: one ROOT, any number of JOINT / End Site blocks, CHANNELS with any
subset and order of ``X/Y/Zposition`` and ``X/Y/Zrotation`` on any joint,
Euler angles in degrees composed in the listed order (``R = R_1 @ R_2 @ R_3``
acting on column vectors, the convention of the format). Position channels
replace the matching component of the joint's OFFSET.

Not supported: several ROOTs (multi-character files), scale channels, files
whose frames span several lines, a ``Frame Time`` over a minute.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.sim.errors import BvhError
from drivers.sim.rotations import euler_to_matrix

#: Longest ``Frame Time`` accepted (seconds).
MAX_FRAME_TIME_S = 60.0

_CHANNELS = {
    "xposition": "Xposition", "yposition": "Yposition", "zposition": "Zposition",
    "xrotation": "Xrotation", "yrotation": "Yrotation", "zrotation": "Zrotation",
}


@dataclass(frozen=True, eq=False)
class BvhJoint:
    """One joint: its parent's index (-1 for the root), OFFSET, CHANNELS and optional End Site."""

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    end_site: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class BvhClip:
    """A parsed BVH file.

    Attributes:
        joints: joints in file order (parents before children).
        frame_time: seconds per frame.
        frames: ``(F, C)`` channel values, C = total channel count in file order.
        source: file path (or ``"<string>"``) for error messages.
    """

    joints: tuple[BvhJoint, ...]
    frame_time: float
    frames: np.ndarray
    source: str = "<string>"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def duration_s(self) -> float:
        return self.num_frames * self.frame_time

    def channel_slices(self) -> list[slice]:
        out, k = [], 0
        for j in self.joints:
            out.append(slice(k, k + len(j.channels)))
            k += len(j.channels)
        return out

    def children(self, index: int) -> list[int]:
        return [k for k, j in enumerate(self.joints) if j.parent == index]

    def rest_positions(self) -> np.ndarray:
        """``(J, 3)`` joint positions with every channel at zero... except that position channels
        of the root are ignored, so the root sits at its OFFSET."""
        pos = np.zeros((len(self.joints), 3))
        for k, j in enumerate(self.joints):
            pos[k] = j.offset if j.parent < 0 else pos[j.parent] + j.offset
        return pos

    def local_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Per frame local rotations ``(F, J, 3, 3)`` and translations ``(F, J, 3)``."""
        F, J = self.num_frames, len(self.joints)
        R = np.broadcast_to(np.eye(3), (F, J, 3, 3)).copy()
        T = np.broadcast_to(np.stack([j.offset for j in self.joints]), (F, J, 3)).copy()
        for k, (joint, sl) in enumerate(zip(self.joints, self.channel_slices())):
            values = self.frames[:, sl]
            rot_cols = [i for i, c in enumerate(joint.channels) if c.endswith("rotation")]
            if rot_cols:
                order = "".join(joint.channels[i][0].lower() for i in rot_cols)
                R[:, k] = euler_to_matrix(values[:, rot_cols], order)
            for i, c in enumerate(joint.channels):
                if c.endswith("position"):
                    T[:, k, "XYZ".index(c[0])] = values[:, i]
        return R, T

    def forward(self) -> tuple[np.ndarray, np.ndarray]:
        """Global rotations ``(F, J, 3, 3)`` and positions ``(F, J, 3)`` of every frame."""
        R, T = self.local_transforms()
        G = np.empty_like(R)
        P = np.empty_like(T)
        for k, j in enumerate(self.joints):
            if j.parent < 0:
                G[:, k], P[:, k] = R[:, k], T[:, k]
            else:
                G[:, k] = G[:, j.parent] @ R[:, k]
                P[:, k] = P[:, j.parent] + np.einsum("fab,fb->fa", G[:, j.parent], T[:, k])
        return G, P


# --------------------------------------------------------------------- parsing
class _Tokens:
    """Whitespace tokens with their 1-based line numbers."""

    def __init__(self, lines: list[str], source: str) -> None:
        self.items = [(tok, n + 1) for n, line in enumerate(lines) for tok in line.replace("{", " { ").replace("}", " } ").split()]
        self.pos = 0
        self.source = source
        self.last_line = len(lines)

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    @property
    def line(self) -> int:
        return self.items[self.pos][1] if self.pos < len(self.items) else self.last_line

    def error(self, message: str, line: int | None = None) -> BvhError:
        return BvhError(self.source, self.line if line is None else line, message)

    def take(self, what: str) -> str:
        if self.pos >= len(self.items):
            raise self.error(f"unexpected end of file, expected {what}")
        tok = self.items[self.pos][0]
        self.pos += 1
        return tok

    def expect(self, keyword: str) -> None:
        line = self.line
        tok = self.take(repr(keyword))
        if tok.upper() != keyword.upper():
            raise self.error(f"expected {keyword!r}, got {tok!r}", line)

    def number(self, what: str) -> float:
        line = self.line
        tok = self.take(what)
        try:
            value = float(tok)
        except ValueError:
            raise self.error(f"expected a number for {what}, got {tok!r}", line) from None
        if not np.isfinite(value):
            raise self.error(f"{what} must be finite, got {tok!r}", line)
        return value


def parse_bvh(text: str, source: str = "<string>") -> BvhClip:
    """Parse BVH text.

    Raises:
        BvhError: malformed input; the message names ``source`` and the line.
    """
    lines = text.splitlines()
    motion_line = next((n for n, line in enumerate(lines) if line.strip().upper().startswith("MOTION")), None)
    if motion_line is None:
        raise BvhError(source, None, "no MOTION section")
    toks = _Tokens(lines[:motion_line], source)
    toks.expect("HIERARCHY")
    joints: list[dict] = []
    line = toks.line
    kind = toks.take("ROOT")
    if kind.upper() != "ROOT":
        raise toks.error(f"expected 'ROOT', got {kind!r}", line)
    _parse_joint(toks, joints, parent=-1)
    if toks.peek() is not None:
        line = toks.line
        tok = toks.take("end of hierarchy")
        if tok.upper() == "ROOT":
            raise toks.error("several ROOT joints (multi-character files) are not supported", line)
        raise toks.error(f"unexpected {tok!r} after the ROOT block", line)
    num_channels = sum(len(j["channels"]) for j in joints)
    frames, frame_time = _parse_motion(lines, motion_line, num_channels, source)
    built = tuple(
        BvhJoint(j["name"], j["parent"], np.asarray(j["offset"], dtype=np.float64), tuple(j["channels"]),
                 None if j["end"] is None else np.asarray(j["end"], dtype=np.float64))
        for j in joints
    )
    names = [j.name for j in built]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise BvhError(source, None, f"duplicate joint names {dupes}")
    return BvhClip(built, frame_time, frames, source)


def _parse_joint(toks: _Tokens, joints: list[dict], parent: int) -> None:
    name_line = toks.line
    name = toks.take("joint name")
    if name in ("{", "}"):
        raise toks.error("missing joint name", name_line)
    me = {"name": name, "parent": parent, "offset": None, "channels": [], "end": None}
    index = len(joints)
    joints.append(me)
    toks.expect("{")
    while True:
        line = toks.line
        tok = toks.take("OFFSET, CHANNELS, JOINT, End Site or '}'")
        key = tok.upper()
        if key == "}":
            break
        if key == "OFFSET":
            me["offset"] = [toks.number(f"OFFSET of {name}") for _ in range(3)]
        elif key == "CHANNELS":
            count_line = toks.line
            count = toks.number(f"CHANNELS count of {name}")
            if count != int(count) or not 0 <= count <= 6:
                raise toks.error(f"CHANNELS count of {name} must be an integer 0..6, got {count:g}", count_line)
            for _ in range(int(count)):
                ch_line = toks.line
                ch = toks.take(f"channel name of {name}")
                if ch.lower() not in _CHANNELS:
                    raise toks.error(f"unknown channel {ch!r} of joint {name} (expected X/Y/Z position or rotation)", ch_line)
                me["channels"].append(_CHANNELS[ch.lower()])
            if len(set(me["channels"])) != len(me["channels"]):
                raise toks.error(f"repeated channel in {me['channels']} of joint {name}", count_line)
        elif key == "JOINT":
            _parse_joint(toks, joints, parent=index)
        elif key == "END":
            site_line = toks.line
            if (toks.take("'Site'")).upper() != "SITE":
                raise toks.error("expected 'Site' after 'End'", site_line)
            toks.expect("{")
            toks.expect("OFFSET")
            me["end"] = [toks.number(f"End Site OFFSET of {name}") for _ in range(3)]
            toks.expect("}")
        else:
            raise toks.error(f"unexpected {tok!r} in joint {name}", line)
    if me["offset"] is None:
        raise toks.error(f"joint {name} (line {name_line}) has no OFFSET")


def _parse_motion(lines: list[str], start: int, num_channels: int, source: str) -> tuple[np.ndarray, float]:
    def header(n: int, label: str) -> str:
        if n >= len(lines):
            raise BvhError(source, len(lines), f"unexpected end of file, expected {label!r}")
        text = lines[n].strip()
        if not text.upper().replace(" ", "").startswith(label.upper().replace(" ", "")):
            raise BvhError(source, n + 1, f"expected {label!r}, got {text!r}")
        return text.split(":", 1)[1].strip() if ":" in text else ""

    n = start + 1
    while n < len(lines) and not lines[n].strip():
        n += 1
    raw = header(n, "Frames:")
    try:
        count = int(raw)
    except ValueError:
        raise BvhError(source, n + 1, f"Frames must be an integer, got {raw!r}") from None
    if count < 1:
        raise BvhError(source, n + 1, f"Frames must be at least 1, got {count}")
    raw = header(n + 1, "Frame Time:")
    try:
        frame_time = float(raw)
    except ValueError:
        raise BvhError(source, n + 2, f"Frame Time must be a number, got {raw!r}") from None
    # At most a minute a frame: no motion clip is slower, and a garbled 1e308 made the clip's length
    # (frames x frame time) infinite, an OverflowError where sim:// sizes its loop.
    if not (np.isfinite(frame_time) and 0 < frame_time <= MAX_FRAME_TIME_S):
        raise BvhError(source, n + 2, f"Frame Time must be positive and at most {MAX_FRAME_TIME_S:g} s, got {raw!r}")
    if count > len(lines) - (n + 2):  # before allocating: a garbled count must not ask for terabytes
        given = sum(1 for line in lines[n + 2:] if line.strip())
        raise BvhError(source, n + 1, f"Frames: {count} but only {given} frame lines")
    frames = np.empty((count, num_channels))
    k = 0
    for m in range(n + 2, len(lines)):
        text = lines[m].strip()
        if not text:
            continue
        if k >= count:
            raise BvhError(source, m + 1, f"more frame lines than Frames: {count}")
        parts = text.split()
        if len(parts) != num_channels:
            raise BvhError(source, m + 1, f"frame {k} has {len(parts)} values, the hierarchy has {num_channels} channels")
        try:
            frames[k] = [float(p) for p in parts]
        except ValueError:
            bad = next(p for p in parts if not _is_float(p))
            raise BvhError(source, m + 1, f"frame {k}: {bad!r} is not a number") from None
        if not np.all(np.isfinite(frames[k])):
            raise BvhError(source, m + 1, f"frame {k} contains a non-finite value")
        k += 1
    if k < count:
        raise BvhError(source, len(lines), f"Frames: {count} but only {k} frame lines")
    return frames, frame_time


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load_bvh(path: str | Path) -> BvhClip:
    """Read and parse a ``.bvh`` file (errors name the file and the line)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="strict")  # -sig: a byte-order mark is no text
    except OSError as e:
        raise BvhError(str(path), None, f"cannot read: {e.strerror or e}") from e
    except UnicodeDecodeError as e:
        raise BvhError(str(path), None, f"not a text file: {e}") from e
    return parse_bvh(text, str(path))


# --------------------------------------------------------------------- writing
def dumps_bvh(clip: BvhClip, precision: int = 6) -> str:
    """BVH text for ``clip`` (values with ``precision`` decimals)."""
    fmt = f"{{:.{precision}f}}"
    num = lambda v: fmt.format(float(v)) if abs(float(v)) >= 0.5 * 10 ** -precision else fmt.format(0.0)  # noqa: E731 - no "-0.000"
    out = ["HIERARCHY"]

    def write(k: int, depth: int) -> None:
        j = clip.joints[k]
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}  OFFSET {' '.join(num(v) for v in j.offset)}")
        out.append(f"{pad}  CHANNELS {len(j.channels)}{''.join(' ' + c for c in j.channels)}")
        for child in clip.children(k):
            write(child, depth + 1)
        if j.end_site is not None:
            out.append(f"{pad}  End Site")
            out.append(f"{pad}  {{")
            out.append(f"{pad}    OFFSET {' '.join(num(v) for v in j.end_site)}")
            out.append(f"{pad}  }}")
        out.append(f"{pad}}}")

    order: list[int] = []
    stack = [0]
    while stack:  # frames are stored in file (depth-first) order; the joints must be too
        k = stack.pop()
        order.append(k)
        stack.extend(reversed(clip.children(k)))
    if order != list(range(len(clip.joints))):
        raise ValueError("dumps_bvh: joints must be listed depth-first from the root, as a file stores them")
    write(0, 0)
    out.append("MOTION")
    out.append(f"Frames: {clip.num_frames}")
    out.append(f"Frame Time: {clip.frame_time:.6f}")
    out.extend(" ".join(num(v) for v in row) for row in clip.frames)
    return "\n".join(out) + "\n"


def save_bvh(clip: BvhClip, path: str | Path, precision: int = 6) -> None:
    Path(path).write_text(dumps_bvh(clip, precision), encoding="utf-8")
