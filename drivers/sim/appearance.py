"""Skin, hair and clothing: colours, garment coverage and procedural textures.

Textures are functions of a point's *rest-pose* position (the body-frame
point the surface point had in the rest pose), so patterns stick to the body
as it moves and stay continuous across overlapping primitives. Colours are
given in sRGB (0..1, as a person would pick them) and converted once to
linear BGR for shading.

Not modelled: specular highlights, subsurface scattering, cloth folds or
wrinkles, fabric normal maps, hair strands, make-up, glasses, logos.
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from drivers.sim.body import BodyModel
from drivers.sim.errors import SimConfigError
from ghnerf_runtime.body25 import JOINT_NAMES

# Material ids used in the primitive layout.
SKIN, HAIR, SHIRT, PANTS, SHOES = range(5)
PATTERNS = ("plain", "stripes", "checks", "heather")
HAIR_STYLES = ("short", "long", "bald")
SLEEVES = ("none", "short", "long")
PANTS_LENGTHS = ("shorts", "long")

_SKIN_TONES = np.array(
    [[0.96, 0.80, 0.69], [0.91, 0.71, 0.58], [0.80, 0.60, 0.45], [0.63, 0.45, 0.32], [0.45, 0.31, 0.21], [0.30, 0.20, 0.14]]
)
_HAIR_COLOURS = np.array(
    [[0.06, 0.05, 0.05], [0.20, 0.13, 0.08], [0.38, 0.25, 0.15], [0.76, 0.63, 0.40], [0.52, 0.24, 0.11], [0.62, 0.62, 0.62]]
)

RGB = tuple[float, float, float]


def _check_rgb(field: str, value) -> None:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 1):
        raise SimConfigError(field, f"must be an (r, g, b) triple in [0, 1], got {value!r}")


@dataclass(frozen=True)
class Fabric:
    """A garment's look.

    Attributes:
        color: main sRGB colour (0..1).
        color2: second colour of the pattern.
        pattern: one of ``plain``, ``stripes``, ``checks``, ``heather``.
        scale_m: pattern period in metres (stripe pitch, check size, heather cell).
    """

    color: RGB = (0.2, 0.35, 0.6)
    color2: RGB = (0.9, 0.9, 0.9)
    pattern: str = "plain"
    scale_m: float = 0.06

    def validate(self, where: str) -> None:
        _check_rgb(f"{where}.color", self.color)
        _check_rgb(f"{where}.color2", self.color2)
        if self.pattern not in PATTERNS:
            raise SimConfigError(f"{where}.pattern", f"must be one of {PATTERNS}, got {self.pattern!r}")
        if not (isinstance(self.scale_m, (int, float)) and 0.005 <= self.scale_m <= 0.5):
            raise SimConfigError(f"{where}.scale_m", f"must be in [0.005, 0.5] m, got {self.scale_m!r}")

    @classmethod
    def random(cls, rng: np.random.Generator) -> "Fabric":
        def colour() -> RGB:
            h, s, v = rng.uniform(0, 1), rng.uniform(0.05, 0.8), rng.uniform(0.12, 0.92)
            return tuple(float(c) for c in colorsys.hsv_to_rgb(h, s, v))

        pattern = PATTERNS[int(rng.choice(4, p=[0.45, 0.2, 0.15, 0.2]))]
        return cls(colour(), colour(), pattern, float(rng.uniform(0.02, 0.12)))


@dataclass(frozen=True)
class Appearance:
    """What the person looks like. Every field is validated; :meth:`random` draws a plausible one.

    Attributes:
        skin, hair, eyes, shoes: sRGB colours (0..1).
        hair_style: ``short``, ``long`` or ``bald``.
        shirt, pants: garment fabrics.
        sleeves: ``none``, ``short`` or ``long``.
        pants_length: ``shorts`` or ``long``.
    """

    skin: RGB = (0.80, 0.60, 0.45)
    hair: RGB = (0.20, 0.13, 0.08)
    eyes: RGB = (0.25, 0.17, 0.10)
    hair_style: str = "short"
    shirt: Fabric = Fabric((0.15, 0.35, 0.65), (0.85, 0.85, 0.85), "stripes", 0.05)
    pants: Fabric = Fabric((0.12, 0.13, 0.2), (0.2, 0.2, 0.25), "heather", 0.02)
    shoes: RGB = (0.85, 0.85, 0.82)
    sleeves: str = "short"
    pants_length: str = "long"

    def __post_init__(self) -> None:
        for name in ("skin", "hair", "eyes", "shoes"):
            _check_rgb(f"Appearance.{name}", getattr(self, name))
        for name, allowed in (("hair_style", HAIR_STYLES), ("sleeves", SLEEVES), ("pants_length", PANTS_LENGTHS)):
            if getattr(self, name) not in allowed:
                raise SimConfigError(f"Appearance.{name}", f"must be one of {allowed}, got {getattr(self, name)!r}")
        for name in ("shirt", "pants"):
            fabric = getattr(self, name)
            if not isinstance(fabric, Fabric):
                raise SimConfigError(f"Appearance.{name}", f"must be a Fabric, got {type(fabric).__name__}")
            fabric.validate(f"Appearance.{name}")

    @classmethod
    def random(cls, rng: np.random.Generator) -> "Appearance":
        k = rng.uniform(0, len(_SKIN_TONES) - 1)
        i = int(min(np.floor(k), len(_SKIN_TONES) - 2))
        skin = (1 - (k - i)) * _SKIN_TONES[i] + (k - i) * _SKIN_TONES[i + 1]
        hair = _HAIR_COLOURS[int(rng.integers(len(_HAIR_COLOURS)))] * rng.uniform(0.85, 1.15)
        eyes = np.array([0.25, 0.17, 0.10]) if rng.uniform() < 0.7 else np.array([0.25, 0.4, 0.5])
        shoe_v = rng.choice([0.08, 0.3, 0.85])
        return cls(
            skin=tuple(float(c) for c in skin),
            hair=tuple(float(c) for c in np.clip(hair, 0, 1)),
            eyes=tuple(float(c) for c in eyes),
            hair_style=HAIR_STYLES[int(rng.choice(3, p=[0.55, 0.35, 0.1]))],
            shirt=Fabric.random(rng),
            pants=Fabric.random(rng),
            shoes=tuple(float(c) for c in np.clip(shoe_v * rng.uniform(0.8, 1.1, 3), 0, 1)),
            sleeves=SLEEVES[int(rng.choice(3, p=[0.15, 0.45, 0.4]))],
            pants_length=PANTS_LENGTHS[int(rng.choice(2, p=[0.25, 0.75]))],
        )

    def zone_layout(self, zone: str) -> tuple[int, int, float]:
        """``(base material, cover material, cover fraction)`` for a body zone.

        The cover material applies from a rounded cone's first sphere up to ``fraction`` of its
        length (sleeves, shorts); ellipsoids use the base material only.
        """
        sleeve = {"none": 0.0, "short": 0.45, "long": 2.0}[self.sleeves]
        legs = {"shorts": 0.5, "long": 2.0}[self.pants_length]
        table = {
            "torso_top": (SHIRT, SHIRT, 0.0),
            "torso_bottom": (PANTS, PANTS, 0.0),
            "neck": (SKIN, SKIN, 0.0),
            "head": (SKIN, SKIN, 0.0),
            "nose": (SKIN, SKIN, 0.0),
            "hair": (HAIR, HAIR, 0.0),
            "upper_arm": (SKIN, SHIRT, sleeve),
            "lower_arm": (SKIN, SHIRT, 2.0 if self.sleeves == "long" else 0.0),
            "hand": (SKIN, SKIN, 0.0),
            "thigh": (SKIN, PANTS, legs),
            "shin": (SKIN, PANTS, 2.0 if self.pants_length == "long" else 0.0),
            "foot": (SHOES, SHOES, 0.0),
        }
        return table[zone]


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.asarray(c, dtype=np.float64) ** 2.2


def cell_noise(q: np.ndarray, salt: float = 0.0) -> np.ndarray:
    """Deterministic pseudo-random value in [0, 1) per integer lattice cell ``q (..., 3)``.

    An integer hash (multiply, xor, shift; int64 wrap-around is intended), which unlike the
    classic ``fract(sin(dot) * 43758)`` stays fast for large cell coordinates.
    """
    i = np.asarray(q).astype(np.int64)
    h = i[..., 0] * 73856093 ^ i[..., 1] * 19349663 ^ i[..., 2] * 83492791 ^ int(salt * 1000.0 + 0.5)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return (h & 0xFFFF).astype(np.float64) * (1.0 / 65536.0)


class Look:
    """An :class:`Appearance` compiled for one body: linear BGR albedos and texture functions.

    Args:
        appearance: the look.
        body: the body it dresses (its rest-pose head geometry places the face).
    """

    def __init__(self, appearance: Appearance, body: BodyModel) -> None:
        self.appearance = appearance
        a = appearance
        bgr = lambda rgb: srgb_to_linear(rgb)[::-1]  # noqa: E731 - tiny local converter
        self.base = {SKIN: bgr(a.skin), HAIR: bgr(a.hair), SHOES: bgr(a.shoes)}
        self.fabrics = {SHIRT: (bgr(a.shirt.color), bgr(a.shirt.color2), a.shirt), PANTS: (bgr(a.pants.color), bgr(a.pants.color2), a.pants)}
        self.eye_colour = bgr(a.eyes)
        head = next(k for k, p in enumerate(body.primitives) if p.zone == "head")
        e = body.ellipsoids[head]
        self.head_center = body.rest_positions[e.joint] + np.asarray(e.center)
        self.head_radii = np.asarray(e.radii)
        self.sole_top = 0.012 * body.skeleton.scale
        layouts = [a.zone_layout(z) for z in body.prim_zone]
        self.prim_base = np.array([m[0] for m in layouts])
        self.prim_cover = np.array([m[1] for m in layouts])
        self.prim_cover_until = np.array([m[2] for m in layouts], dtype=np.float64)
        self.head_prim = head
        # Paint the eyes where the BODY_25 eye joints are (unit-sphere coordinates of the head).
        eyes = [JOINT_NAMES.index("REye"), JOINT_NAMES.index("LEye")]
        self.eye_units = (body.landmark_offset[eyes] - np.asarray(e.center)) / self.head_radii

    # ------------------------------------------------------------------ albedo
    def albedo(self, material: int, rest: np.ndarray) -> np.ndarray:
        """Linear BGR albedo ``(n, 3)`` of ``material`` at rest-pose points ``rest (n, 3)``."""
        if material in self.fabrics:
            c1, c2, fabric = self.fabrics[material]
            mix = _pattern(fabric.pattern, rest, fabric.scale_m, salt=float(material))
            out = c1 + mix[:, None] * (c2 - c1)
            # Fine weave noise so plain garments are not flat.
            grain = cell_noise(np.floor(rest / 0.004), salt=3.0 + material)
            return out * (0.94 + 0.12 * grain)[:, None]
        if material == SHOES:
            out = np.broadcast_to(self.base[SHOES], rest.shape).copy()
            sole = rest[:, 1] < self.sole_top
            out[sole] = self.base[SHOES] * 0.25 + 0.05
            return out
        if material == HAIR:
            streak = cell_noise(np.floor(rest / np.array([0.003, 0.03, 0.003])), salt=7.0)
            return self.base[HAIR] * (0.75 + 0.5 * streak)[:, None]
        mottle = cell_noise(np.floor(rest / 0.01), salt=11.0)
        return self.base[SKIN] * (0.96 + 0.06 * mottle)[:, None]

    def face_albedo(self, rest: np.ndarray) -> np.ndarray:
        """Albedo of the head ellipsoid: skin with hair, eyes, eyebrows and mouth."""
        out = self.albedo(SKIN, rest)
        s = (rest - self.head_center) / self.head_radii  # unit-sphere coordinates (x left, y up, z fwd)
        sx, sy, sz = s[:, 0], s[:, 1], s[:, 2]
        style = self.appearance.hair_style
        if style != "bald":
            drop = 1.35 if style == "long" else 0.85
            hairline = 0.45 + 0.12 * sz - drop * np.maximum(0.0, -sz) - (0.25 if style == "long" else 0.0) * (1 - np.abs(sz))
            hair = sy > hairline
            out[hair] = self.albedo(HAIR, rest[hair])
        for ex, ey, _ in self.eye_units:
            r2 = ((sx - ex) / 0.13) ** 2 + ((sy - ey) / 0.07) ** 2
            front = sz > 0.5
            out[front & (r2 < 1.0)] = np.array([0.75, 0.78, 0.8])
            out[front & (r2 < 0.3)] = self.eye_colour
            out[front & (r2 < 0.06)] = 0.01
            brow = front & (np.abs(sx - ex) < 0.15) & (np.abs(sy - (ey + 0.15)) < 0.03)
            out[brow] = self.base[HAIR] * 0.8
        mouth = (sz > 0.5) & (np.abs(sx) < 0.19) & (np.abs(sy + 0.5) < 0.03)
        out[mouth] = self.base[SKIN] * np.array([0.45, 0.45, 0.8])
        return out


def _pattern(pattern: str, rest: np.ndarray, scale: float, salt: float) -> np.ndarray:
    """Weight of the second colour (0..1) for a fabric pattern at rest-pose points."""
    if pattern == "plain":
        return np.zeros(len(rest))
    if pattern == "stripes":
        return (np.floor(rest[:, 1] / scale).astype(np.int64) & 1).astype(np.float64)
    if pattern == "checks":
        u = (rest[:, 0] + rest[:, 2]) / scale
        v = rest[:, 1] / scale
        # A simple tartan: two crossing bands of the second colour.
        return np.maximum((u - np.floor(u)) < 0.35, (v - np.floor(v)) < 0.35) * (0.55 + 0.45 * (((u - np.floor(u)) < 0.35) & ((v - np.floor(v)) < 0.35)))
    return 0.5 * cell_noise(np.floor(rest / scale), salt=salt)  # heather
