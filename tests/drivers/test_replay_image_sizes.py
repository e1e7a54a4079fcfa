"""``replay://`` measures every image of a take at open, from its header: a take resized in part is refused there,
and a header cut short is left to its read (a corrupt frame). The size reader itself, against OpenCV's decoder."""
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers import EndOfStream, FrameSizeError, RigOperationError, create_rig_source, open_rig
from drivers.backends.recording_format import (
    FRAMES,
    IMAGE_FORMATS,
    MANIFEST,
    FrameRow,
    Manifest,
    encode_image,
    header_size,
    image_size,
    write_manifest,
)
from drivers.sim.placement import RigPlacement

WIDTH, HEIGHT = 40, 30
FRAMES_A_CAMERA = 50


def write_take(directory: Path, image_format: str, frames: int = FRAMES_A_CAMERA) -> Path:
    """A closed take of ``frames`` frames a camera, laid out as ``record+`` writes one (no truth)."""
    rig = RigPlacement(width=WIDTH, height=HEIGHT).build()
    rows = []
    for n in range(frames):
        for k, cam in enumerate(rig.pair):
            rel = f"images/{cam.name}/{n:08d}{IMAGE_FORMATS[image_format]}"
            (directory / rel).parent.mkdir(parents=True, exist_ok=True)
            image = np.full((HEIGHT, WIDTH, 3), (n * 5) % 256, np.uint8)
            (directory / rel).write_bytes(encode_image(image, image_format, 90))
            rows.append(FrameRow(cam.name, n, n * 33_333_333 + k * 1_000, rel))
    (directory / FRAMES).write_text("".join(row.to_json() + "\n" for row in rows))
    write_manifest(directory, Manifest(rig, image_format, "test", "", complete=True))
    return directory


def image_of(take: Path, camera: str, n: int) -> Path:
    return next((take / "images" / camera).glob(f"{n:08d}.*"))


def resize(path: Path, size: tuple[int, int]) -> None:
    """Rescaled to ``size`` (width, height) and written in its own format, as an image tool would."""
    assert cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), size))


def play(take: Path) -> tuple[int, list[RigOperationError]]:
    """The pairs a free-running replay of ``take`` delivers and the read errors it raised, to the end."""
    pairs, errors = 0, []
    with open_rig(f"replay://{take}?speed=free&policy=all") as source:
        while True:
            try:
                source.read(timeout_s=1.0)
                pairs += 1
            except EndOfStream:
                return pairs, errors
            except RigOperationError as e:
                errors.append(e)


# ------------------------------------------------------------------ takes
@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
def test_a_take_of_the_rig_s_size_opens_and_plays_every_pair(tmp_path, image_format):
    take = write_take(tmp_path / "take", image_format)
    assert play(take) == (FRAMES_A_CAMERA, [])


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
def test_a_take_with_one_image_in_fifty_resized_mid_take_is_refused_at_open(tmp_path, image_format):
    """The open sampled a camera's first, middle and last images: one resized elsewhere passed, and played as a
    corrupt frame skipped (a take resized in part, as many). Every image's header is read now."""
    take = write_take(tmp_path / "take", image_format)
    resized = image_of(take, "right", 20)  # not the first, the middle (25) nor the last (49)
    resize(resized, (20, 15))
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(FrameSizeError) as info:
        source.open()
    error = info.value
    assert (error.camera, error.expected, error.delivered) == ("right", (WIDTH, HEIGHT), (20, 15))
    rel = resized.relative_to(take).as_posix()
    assert str(error).startswith(
        f"recording {take}: camera 'right': 1 of its {FRAMES_A_CAMERA} images is 20x15 ({rel}; read from each "
        f"image's header at open), but its rig camera in {take / MANIFEST} is {WIDTH}x{HEIGHT}: the take was "
        "recorded at another size than the rig it carries, its images (all or some) were resized after")
    assert not source.is_open


def test_the_refusal_counts_the_images_of_another_size_and_names_the_first_three_and_each_size(tmp_path):
    take = write_take(tmp_path / "take", "png")
    for n, size in [(3, (20, 15)), (7, (20, 15)), (11, (80, 60)), (30, (20, 15))]:
        resize(image_of(take, "left", n), size)
    with pytest.raises(FrameSizeError) as info:
        create_rig_source(f"replay://{take}").open()
    names = ", ".join(f"images/left/{n:08d}.png" for n in (3, 7, 11))
    assert f"camera 'left': 4 of its {FRAMES_A_CAMERA} images are 20x15 (3) and 80x60 (1) ({names}, ...; " \
        in str(info.value)
    assert info.value.delivered == (20, 15)  # the first in recorded order


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
def test_a_take_with_an_image_header_cut_short_opens_and_the_frame_is_skipped_when_read(tmp_path, image_format):
    """A header that cannot be read is no size (decoded instead, it does not decode): not a reason to refuse the
    take, and not an error at open; its read fails once, naming it, and the take plays on."""
    take = write_take(tmp_path / "take", image_format)
    cut = image_of(take, "left", 20)
    cut.write_bytes(cut.read_bytes()[:12])
    assert header_size(cut) is None and image_size(cut) is None
    pairs, errors = play(take)
    assert [type(e) for e in errors] == [RigOperationError]
    assert str(cut) in str(errors[0]) and "corrupt" in str(errors[0])
    assert pairs == FRAMES_A_CAMERA - 1


def test_an_image_resized_after_the_open_is_a_corrupt_frame_and_the_take_plays_on(tmp_path):
    """The open measured every image; one changed since fails its read once, not as a FrameSizeError (a daemon
    stops on those), and the next read goes on to the end."""
    take = write_take(tmp_path / "take", "png")
    edited = image_of(take, "left", 10)
    pairs, errors = 0, []
    with open_rig(f"replay://{take}?speed=free&policy=all") as source:
        resize(edited, (10, 10))
        while True:
            try:
                source.read(timeout_s=1.0)
                pairs += 1
            except EndOfStream:
                break
            except RigOperationError as e:
                errors.append(e)
    assert [type(e) for e in errors] == [RigOperationError]
    assert str(errors[0]).startswith(f"recording image {edited} is 10x10, but the rig's camera 'left' is 40x30 as the "
                                     "take's images were at open: this file was corrupted or edited since")
    assert pairs == FRAMES_A_CAMERA - 1


# ------------------------------------------------------------------ the size reader
def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _exif_turned(orientation: int) -> bytes:
    """A big-endian TIFF block holding one tag, the EXIF orientation."""
    return b"MM\x00*\x00\x00\x00\x08" + struct.pack(">HHHIHH", 1, 0x0112, 3, 1, orientation, 0) + b"\x00" * 4


def with_exif(data: bytes, fmt: str) -> bytes:
    """``data`` (a PNG or JPEG) with EXIF saying the image is to be turned a quarter (orientation 6)."""
    if fmt == "png":
        return data[:33] + _png_chunk(b"eXIf", _exif_turned(6)) + data[33:]  # after the signature and IHDR
    app1 = b"Exif\x00\x00" + _exif_turned(6)
    return data[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + data[2:]


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
@pytest.mark.parametrize(("width", "height", "channels"), [(1, 1, 3), (40, 30, 3), (641, 479, 1), (3000, 17, 3)])
def test_the_header_gives_the_size_opencv_decodes(tmp_path, image_format, width, height, channels):
    image = np.random.default_rng(width).integers(0, 256, (height, width, channels), np.uint8)
    path = tmp_path / f"image{IMAGE_FORMATS[image_format]}"
    path.write_bytes(encode_image(image, image_format, 90))
    assert header_size(path) == (width, height) == image_size(path)


def test_a_progressive_jpeg_and_a_16_bit_png_are_read_from_their_headers(tmp_path):
    rng = np.random.default_rng(1)
    progressive, deep = tmp_path / "p.jpg", tmp_path / "d.png"
    assert cv2.imwrite(str(progressive), rng.integers(0, 256, (30, 40, 3), np.uint8), [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
    assert cv2.imwrite(str(deep), rng.integers(0, 65535, (30, 40), np.uint16))
    assert header_size(progressive) == header_size(deep) == (40, 30)


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
def test_an_image_with_exif_is_decoded_as_opencv_turns_it_by_its_orientation(tmp_path, image_format):
    """OpenCV applies the EXIF orientation: a 40x30 image marked as turned decodes 30x40. The header's size would
    be wrong, so such a file is decoded instead."""
    path = tmp_path / f"image{IMAGE_FORMATS[image_format]}"
    path.write_bytes(with_exif(encode_image(np.zeros((30, 40, 3), np.uint8), image_format, 90), image_format))
    assert header_size(path) is None
    assert image_size(path) == (30, 40)


def test_another_format_is_decoded(tmp_path):
    path = tmp_path / "image.bmp"
    assert cv2.imwrite(str(path), np.zeros((30, 40, 3), np.uint8))
    assert header_size(path) is None and image_size(path) == (40, 30)


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
def test_a_header_cut_anywhere_or_corrupt_never_raises_and_never_gives_a_size_opencv_would_not(tmp_path, image_format):
    """Every cut of the first 200 bytes, and each byte of them set to 0x00 or 0xFF: no exception, and any size
    read is the size OpenCV decodes (where it decodes). A PNG's IHDR is checked against its CRC."""
    data = encode_image(np.random.default_rng(2).integers(0, 256, (30, 40, 3), np.uint8), image_format, 90)
    damaged = [data[:n] for n in range(200)]
    damaged += [data[:i] + bytes([value]) + data[i + 1:] for i in range(200) for value in (0x00, 0xFF)]
    path = tmp_path / f"image{IMAGE_FORMATS[image_format]}"
    for content in damaged:
        path.write_bytes(content)
        size = header_size(path)
        if size is not None:
            decoded = cv2.imdecode(np.frombuffer(content, np.uint8), cv2.IMREAD_COLOR) if content else None
            assert decoded is None or size == (decoded.shape[1], decoded.shape[0])
    assert header_size(tmp_path / "missing.png") is None
