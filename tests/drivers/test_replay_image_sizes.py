"""``replay://`` measures every image of a take at open, from its header: a take resized in part is refused there,
and a header cut short is left to its read (a corrupt frame). The size reader itself, against OpenCV's decoder."""
import re
import struct
import threading
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers import (
    EndOfStream, FrameSizeError, RigInitializationError, RigOperationError, create_rig_source, open_rig,
)
from drivers.backends import recording_format
from drivers.backends import replay as replay_backend
from drivers.backends.recording_format import (
    FRAMES,
    IMAGE_FORMATS,
    MANIFEST,
    FrameRow,
    Manifest,
    encode_image,
    header_size,
    image_size,
    load_image,
    write_manifest,
)
from drivers.sim.placement import RigPlacement
from tests.drivers.contract import opened_in_a_thread
from tests.exif_images import exif_orientation, jpeg_segment, jpeg_turned, png_turned
from ghnerf_runtime import image_files
from tests.odd_images import (
    avif_transform,
    avif_with_properties,
    bmp_beyond_opencv_s_limits,
    bmp_built,
    isobmff_boxes,
    riff_chunk,
    tiff_entries,
    tiff_laid_out,
    tiff_tiled,
    webp_extended,
)

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


def test_a_close_from_another_thread_cancels_the_open_measuring_the_take_s_images(tmp_path, monkeypatch):
    """A close() while open() read every image's header did nothing (the base class closes only an open source): the
    open measured the whole take on (thousands of files, on an SD card), then returned a closed source. It stops at
    its next file now, and raises."""
    take = write_take(tmp_path / "take", "png")
    measuring, closed = threading.Event(), threading.Event()
    measured = []

    def first_image_held_until_the_close(path):
        measured.append(path)
        measuring.set()
        assert closed.wait(30)
        return image_size(path)

    monkeypatch.setattr(replay_backend, "image_size", first_image_held_until_the_close)
    source = create_rig_source(f"replay://{take}")
    opener, failed = opened_in_a_thread(source)
    assert measuring.wait(30)
    source.close()
    closed.set()
    opener.join(timeout=60)
    assert not opener.is_alive()
    assert len(failed) == 1 and isinstance(failed[0], RigInitializationError), failed
    assert "closed while open() checked" in str(failed[0])
    assert len(measured) == 1 and not source.is_open, measured


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
def with_exif(data: bytes, fmt: str, orientation: int = 6) -> bytes:
    """``data`` (a PNG or JPEG) with EXIF saying the image is to be turned (6: a quarter, as a phone held upright
    writes it; 3: half a turn), placed as a phone writes it (a JPEG's APP1 first, before JFIF's APP0 if any)."""
    if fmt == "png":
        return png_turned(data, orientation)
    return jpeg_turned(data, orientation)


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


@pytest.fixture
def no_decode(monkeypatch):
    """``image_size`` may not decode: its size must come from the header."""
    def refused(path):
        raise AssertionError(f"{path} was decoded to measure it")
    monkeypatch.setattr(recording_format, "load_image", refused)


@pytest.mark.parametrize("image_format", sorted(IMAGE_FORMATS))
@pytest.mark.parametrize("orientation", [3, 6, 8])
def test_an_image_with_exif_is_measured_from_its_header_and_decoded_as_stored(tmp_path, image_format, orientation):
    """The EXIF orientation is ignored (load_image): a 40x30 image marked as turned decodes 40x30, its pixels as
    stored, so its header gives its size. OpenCV turned it by its tag, and the file was decoded to measure it."""
    image = np.zeros((30, 40, 3), np.uint8)
    image[:10] = 255  # the top rows white: a half turn would put them at the bottom
    path = tmp_path / f"image{IMAGE_FORMATS[image_format]}"
    path.write_bytes(with_exif(encode_image(image, image_format, 90), image_format, orientation))
    decoded = load_image(path)
    assert decoded.shape == (30, 40, 3)
    assert decoded[:5].min() > 200 and decoded[-5:].max() < 50
    assert header_size(path) == (40, 30) == image_size(path)


def test_a_jpeg_s_segments_before_its_frame_header_are_walked_past(tmp_path, no_decode):
    """As other tools write them: JFIF's APP0, EXIF holding a thumbnail (a JPEG of another size, its own frame
    header inside the APP1 segment), XMP, an ICC profile (APP2), comments, fill bytes before markers."""
    thumbnail = encode_image(np.zeros((6, 8, 3), np.uint8), "jpg", 90)
    exif = b"Exif\x00\x00" + exif_orientation(6) + thumbnail
    data = encode_image(np.random.default_rng(3).integers(0, 256, (30, 40, 3), np.uint8), "jpg", 90)
    segments = (jpeg_segment(0xE1, exif) + jpeg_segment(0xFE, b"a comment\xff\xd9")
                + b"\xff\xff\xff" + jpeg_segment(0xE1, b"http://ns.adobe.com/xap/1.0/\x00<x/>")
                + jpeg_segment(0xE2, b"ICC_PROFILE\x00" + bytes(200)) + jpeg_segment(0xFE, b""))
    path = tmp_path / "phone.jpg"
    path.write_bytes(data[:2] + segments + data[2:])
    assert cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION).shape \
        == (30, 40, 3)
    assert header_size(path) == (40, 30) == image_size(path)


def test_the_benchmark_s_phone_jpeg_is_measured_from_its_header_and_built_by_the_tests_segment_builder(tmp_path,
                                                                                                      no_decode):
    """benchmarks/time_replay_open.py --format exif-jpg times a take of these (docs/recording-format.md): each must be
    read from its header, or the open it times decodes. Its JPEG segment builder is the tests' (tests/exif_images.py
    had a copy of its own)."""
    import tests.exif_images
    from benchmarks import time_replay_open

    assert tests.exif_images.jpeg_segment is time_replay_open.jpeg_segment
    image = np.random.default_rng(5).integers(0, 256, (30, 40, 3), np.uint8)
    path = tmp_path / "phone.jpg"
    path.write_bytes(time_replay_open.encoded(image, "exif-jpg", encode_image(np.zeros((12, 16, 3), np.uint8),
                                                                              "jpg", 80)))
    assert header_size(path) == (40, 30) == image_size(path)


@pytest.mark.parametrize("take_format", ["tiff", "webp"])
def test_the_benchmark_s_tiff_and_webp_are_measured_from_their_headers(tmp_path, no_decode, take_format):
    """benchmarks/time_replay_open.py --format tiff|webp times takes of these (docs/recording-format.md)."""
    from benchmarks import time_replay_open

    image = np.random.default_rng(6).integers(0, 256, (30, 40, 3), np.uint8)
    path = tmp_path / f"image{time_replay_open.TAKE_FORMATS[take_format][1]}"
    path.write_bytes(time_replay_open.encoded(image, take_format, b""))
    assert header_size(path) == (40, 30) == image_size(path)


def test_a_jpeg_cut_short_in_a_segment_before_its_frame_header_has_no_header_size(tmp_path):
    data = encode_image(np.zeros((30, 40, 3), np.uint8), "jpg", 90)
    whole = with_exif(data, "jpg")
    path = tmp_path / "cut.jpg"
    for end in (4, 6, 20, len(whole) - len(data) + 1):  # in APP1's length, its data; just past it
        path.write_bytes(whole[:end])
        assert header_size(path) is None and image_size(path) is None


def bmp(image: np.ndarray, *, top_down: bool = False) -> bytes:
    """``image`` as OpenCV writes a BMP (rows bottom-up, a positive height), or turned into one stored top-down
    (a negative height, the rows in reading order), as some tools write them."""
    ok, buf = cv2.imencode(".bmp", image)
    assert ok
    data = bytearray(buf.tobytes())
    if top_down:
        offset, height = struct.unpack_from("<I", data, 10)[0], struct.unpack_from("<i", data, 22)[0]
        row = (len(data) - offset) // height
        rows = [data[offset + i * row:offset + (i + 1) * row] for i in range(height)]
        data[offset:] = b"".join(reversed(rows))
        struct.pack_into("<i", data, 22, -height)
    return bytes(data)


@pytest.mark.parametrize("top_down", [False, True])
@pytest.mark.parametrize(("width", "height", "channels"), [(1, 1, 3), (40, 30, 3), (41, 29, 1), (3000, 17, 4)])
def test_a_bmp_is_measured_from_its_info_header(tmp_path, no_decode, width, height, channels, top_down):
    image = np.random.default_rng(width).integers(0, 256, (height, width, channels), np.uint8)
    path = tmp_path / "image.bmp"
    path.write_bytes(bmp(image, top_down=top_down))
    decoded = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(decoded.reshape(image.shape), image)  # rows in their order either way
    assert header_size(path) == (width, height) == image_size(path)


def test_a_bmp_cut_short_or_of_a_layout_opencv_does_not_read_has_no_header_size(tmp_path):
    data = bmp(np.zeros((30, 40, 3), np.uint8))
    path = tmp_path / "image.bmp"
    for end in range(34):
        path.write_bytes(data[:end])
        assert header_size(path) is None
    for offset, field, value in [(14, "<I", 12), (28, "<H", 2), (30, "<I", 4), (18, "<i", 0), (22, "<i", 0)]:
        changed = bytearray(data)  # an OS/2 header, 2 bits a pixel, JPEG inside, no width, no height
        struct.pack_into(field, changed, offset, value)
        path.write_bytes(bytes(changed))
        assert header_size(path) is None


def bmp_variants(bits: int, compression: int):
    """Each way a writer lays out a BMP of this layout: for BI_BITFIELDS, each set of masks inside the header (V2
    to V5), after it, or both; for a palette, a colours-used count within OpenCV's 256 or beyond it."""
    if compression == 3:
        for masks in (["565", "555", "444"] if bits == 16 else ["888"]):
            for inside, after in [(True, False), (False, True), (True, True)]:
                yield {"masks": masks, "masks_in_header": inside, "masks_after_header": after}
    elif bits <= 8:
        yield from ({"colours_used": n} for n in (0, 1 << bits, 257))
    else:
        yield {}


def opencv_decoded_size(path: Path) -> tuple[int, int] | None:
    try:
        image = load_image(path)
    except RigOperationError:
        return None
    return image.shape[1], image.shape[0]


@pytest.mark.parametrize(("bits", "compression"), sorted(recording_format._BMP_LAYOUTS))
def test_a_bmp_s_header_gives_a_size_exactly_where_opencv_decodes_it_to_that_size(tmp_path, bits, compression):
    """Every info header size accepted (40 to V5's 124) and every layout, built byte by byte. A 16-bit
    BI_BITFIELDS file with a header above 40 bytes was given a size, yet OpenCV 5.0 reads its masks after the
    header (where a V4/V5 file has its pixels) and does not decode it; nor one with 4-4-4 masks, nor a palette
    of more than 256 colours used."""
    path = tmp_path / "image.bmp"
    wrong = []
    for info_size in recording_format._BMP_INFO_SIZES:
        for variant in bmp_variants(bits, compression):
            if variant.get("masks_in_header") and info_size < 52:
                continue  # no room for masks inside it
            path.write_bytes(bmp_built(bits, compression, info_size, **variant))
            if header_size(path) != opencv_decoded_size(path):
                wrong.append((info_size, variant, header_size(path), opencv_decoded_size(path)))
    assert wrong == []


def test_a_v5_bmp_with_its_16_bit_masks_in_its_header_only_is_decoded_not_read_from_its_header(tmp_path):
    path = tmp_path / "image.bmp"
    path.write_bytes(bmp_built(16, 3, 124, masks="565", masks_in_header=True))
    assert header_size(path) is None and image_size(path) is None
    path.write_bytes(bmp_built(16, 3, 124, masks="565", masks_in_header=True, masks_after_header=True))
    assert header_size(path) == (5, 3) == image_size(path)


def beyond_opencv_s_limits(image_format: str) -> bytes:
    """A 40x30 image whose header says it is 2**21 wide (OpenCV's limit is 2**20), its PNG IHDR's CRC redone."""
    if image_format == "bmp":
        return bmp_beyond_opencv_s_limits()
    data = bytearray(encode_image(np.zeros((30, 40, 3), np.uint8), "png", 90))
    struct.pack_into(">I", data, 16, 1 << 21)
    struct.pack_into(">I", data, 29, zlib.crc32(data[12:29]))
    return bytes(data)


@pytest.mark.parametrize("image_format", ["bmp", "png"])
def test_an_image_beyond_opencv_s_size_limits_is_no_size_and_a_corrupt_frame(tmp_path, image_format):
    """OpenCV raises (not fails) on a header beyond its limits: a BMP's escaped the open as a cv2.error, a PNG's
    was a size (a take refused for it) where the image does not decode."""
    path = tmp_path / f"image.{image_format}"
    path.write_bytes(beyond_opencv_s_limits(image_format))
    assert header_size(path) is None and image_size(path) is None
    with pytest.raises(RigOperationError, match=f"recording image {path} is corrupt"):
        load_image(path)


@pytest.mark.parametrize("dtype", [np.float32, np.int32])
def test_a_tiff_of_samples_that_do_not_decode_to_8_bits_is_named_by_its_sample_type_not_corrupt(tmp_path, capfd,
                                                                                                   dtype):
    """A valid float or 32-bit integer TIFF in a take was "corrupt" (under libtiff's "Sorry, can not handle images
    with 32-bit samples"): its frame's error now names its samples, with nothing from libtiff."""
    path = tmp_path / "image.tiff"
    assert cv2.imwrite(str(path), np.zeros((6, 8), dtype))
    said = f"recording image {path} does not decode: it has {np.dtype(dtype).name} samples (8x6, 1 channel)"
    with pytest.raises(RigOperationError, match=re.escape(said)):
        load_image(path)
    captured = capfd.readouterr()
    assert "Sorry" not in captured.err + captured.out



def test_a_jpeg_cut_short_is_corrupt_not_a_layout_this_opencv_refuses(tmp_path):
    """imdecode refuses a JPEG cut short mid-scan, which the file reader fills in grey: the cause read from the
    file said "it has uint8 samples (...): only 8- or 16-bit images decode to 8 bits", a RefusedLayoutError."""
    image = np.random.default_rng(0).integers(0, 255, (120, 160, 3), np.uint8)
    whole = cv2.imencode(".jpg", image)[1].tobytes()
    path = tmp_path / "image.jpg"
    path.write_bytes(whole[:len(whole) // 2])
    assert image_files.samples_not_8_bit(path) is None
    with pytest.raises(RigOperationError, match=f"^recording image {re.escape(str(path))} is corrupt") as info:
        load_image(path)
    assert not isinstance(info.value, recording_format.RefusedLayoutError)

def test_another_format_is_decoded(tmp_path):
    path = tmp_path / "image.ppm"
    assert cv2.imwrite(str(path), np.zeros((30, 40, 3), np.uint8))
    assert header_size(path) is None and image_size(path) == (40, 30)


#: The TIFF compressions OpenCV writes and decodes: none, LZW, JPEG, Adobe deflate, PackBits, old deflate.
TIFF_COMPRESSIONS = (1, 5, 7, 8, 32773, 32946)


def tiff_variants():
    """(size, channels, dtype, compression) of TIFFs OpenCV writes: 8 and 16 bits (decoded), 32-bit float (not)."""
    for size in ((1, 1), (41, 30), (641, 479), (3000, 17)):
        for channels in (1, 3, 4):
            for dtype in (np.uint8, np.uint16, np.int16, np.float16, np.float32):
                for compression in TIFF_COMPRESSIONS:
                    if compression != 7 or (dtype == np.uint8 and size[1] % 8 == 6):  # JPEG: 8-bit, strips of 8k
                        yield size, channels, dtype, compression


def test_a_tiff_s_header_gives_the_size_opencv_decodes_and_none_where_it_does_not_decode(tmp_path, no_decode):
    """Each layout cv2.imwrite writes: the first directory's width and height, exactly where cv2.imread decodes
    the file (as load_image: 8 bits, as stored); float samples it does not decode are no size (decoded to tell)."""
    path, wrong, sizes = tmp_path / "image.tiff", [], 0
    for (width, height), channels, dtype, compression in tiff_variants():
        image = (np.random.default_rng(width).random((height, width, channels)) * 200).astype(dtype)
        assert cv2.imwrite(str(path), image, [cv2.IMWRITE_TIFF_COMPRESSION, compression])
        decoded = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        size = header_size(path)
        sizes += size is not None
        if size != (None if decoded is None else (decoded.shape[1], decoded.shape[0])):
            wrong.append((width, height, channels, dtype.__name__, compression, size))
    assert wrong == [] and sizes > 200


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize(("big", "size_type"), [(False, 3), (False, 4), (True, 3), (True, 4), (True, 16)],
                         ids=["classic-short", "classic-long", "bigtiff-short", "bigtiff-long", "bigtiff-long8"])
def test_a_tiff_of_either_byte_order_classic_or_big_is_measured_from_its_first_directory(tmp_path, no_decode,
                                                                                          order, big, size_type):
    image = np.random.default_rng(7).integers(0, 256, (30, 41, 3), np.uint8)
    data = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 5])[1].tobytes()
    path = tmp_path / "image.tif"
    path.write_bytes(tiff_laid_out(data, order, big, {256: (size_type, (41,)), 257: (size_type, (30,))}))
    decoded = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    assert np.array_equal(decoded, image)
    assert header_size(path) == (41, 30) == image_size(path)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_a_tiff_tagged_with_any_orientation_is_measured_from_its_header_and_decoded_as_stored(tmp_path, no_decode,
                                                                                           orientation):
    """OpenCV's TIFF decoder turns an image by its Orientation tag even with IMREAD_IGNORE_ORIENTATION (unlike EXIF
    in a JPEG, PNG or WebP); load_image decodes it with the tag set to 1 (ghnerf_runtime.image_files), so the
    stored pixels are delivered and the header's size is theirs. Session 62 decoded such a file at every open to
    measure it, and delivered it turned (30x41 for tags 5 to 8)."""
    image = np.random.default_rng(orientation).integers(0, 256, (30, 41, 3), np.uint8)
    path = tmp_path / "image.tiff"
    path.write_bytes(tiff_laid_out(cv2.imencode(".tiff", image)[1].tobytes(), changed={274: (3, (orientation,))}))
    assert np.array_equal(load_image(path), image)
    assert header_size(path) == (41, 30) == image_size(path)


def test_a_tiff_of_a_compression_opencv_does_not_decode_or_without_its_size_has_no_header_size(tmp_path):
    data = cv2.imencode(".tiff", np.zeros((30, 41, 3), np.uint8))[1].tobytes()
    path = tmp_path / "image.tiff"
    for changed in ({259: (3, (34925,))}, {256: None}, {257: (4, (30, 30))}, {258: (3, (32, 32, 32))}):
        path.write_bytes(tiff_laid_out(data, changed=changed))
        assert header_size(path) is None, changed


def test_a_tiff_s_offsets_and_counts_beyond_any_file_give_no_size_and_raise_nothing(tmp_path):
    """A corrupt BigTIFF's 64-bit offsets and counts: too large to seek to or read as one buffer (a ValueError or
    OverflowError out of the open before they were read within the file's length)."""
    big = b"II+\x00" + struct.pack("<HHQ", 8, 0, 16)
    path = tmp_path / "image.tif"
    for data in (b"II+\x00" + struct.pack("<HHQ", 8, 0, 2**64 - 1), big + struct.pack("<Q", 2**62),
                 big + struct.pack("<QHHQQ", 1, 258, 3, 16, 2**64 - 1), b"II*\x00" + struct.pack("<I", 2**32 - 1)):
        path.write_bytes(data)
        assert header_size(path) is None


def webp_variants() -> dict[str, bytes]:
    """A 41x30 WebP as cv2.imwrite writes it (lossy, lossless, with alpha: lossy or lossless) and extended
    (VP8X) with an EXIF orientation of 6 after its image, as a phone writes it."""
    image = np.random.default_rng(8).integers(0, 256, (30, 41, 4), np.uint8)
    lossy, lossless = [cv2.IMWRITE_WEBP_QUALITY, 90], [cv2.IMWRITE_WEBP_QUALITY, 101]
    files = {"lossy": cv2.imencode(".webp", image[..., :3], lossy)[1].tobytes(),
             "lossless": cv2.imencode(".webp", image[..., :3], lossless)[1].tobytes(),
             "lossy with alpha": cv2.imencode(".webp", image, lossy)[1].tobytes(),
             "lossless with alpha": cv2.imencode(".webp", image, lossless)[1].tobytes()}
    exif = riff_chunk(b"EXIF", exif_orientation(6))
    files |= {f"{name} with exif": webp_extended(files[name], flags=0x08, after=exif) for name in ("lossy", "lossless")}
    return files


@pytest.mark.parametrize("kind", sorted(webp_variants()))
def test_a_webp_s_header_gives_the_size_opencv_decodes_as_stored(tmp_path, no_decode, kind):
    path = tmp_path / "image.webp"
    path.write_bytes(webp_variants()[kind])
    decoded = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    assert decoded.shape == (30, 41, 3)
    assert header_size(path) == (41, 30) == image_size(path)


def test_a_webp_s_header_gives_the_size_opencv_decodes_for_many_sizes(tmp_path, no_decode):
    path = tmp_path / "image.webp"
    for width, height in ((1, 1), (2, 3), (641, 479), (3000, 17), (16383, 2)):
        image = np.random.default_rng(width).integers(0, 256, (height, width, 3), np.uint8)
        for quality in (50, 101):
            assert cv2.imwrite(str(path), image, [cv2.IMWRITE_WEBP_QUALITY, quality])
            decoded = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
            assert header_size(path) == (decoded.shape[1], decoded.shape[0]) == (width, height)


def test_an_animated_webp_or_one_whose_canvas_is_not_its_image_s_size_is_decoded_to_measure_it(tmp_path):
    simple = webp_variants()["lossy"]
    path = tmp_path / "image.webp"
    for data in (webp_extended(simple, flags=0x02), webp_extended(simple, canvas=(40, 30)),
                 b"RIFF" + simple[4:8] + b"WAVE" + simple[12:]):
        path.write_bytes(data)
        assert header_size(path) is None


#: The file suffix of a format ``encoded_as`` writes, where it is not the format's name.
SUFFIXES = {"tiff-turned": "tif"}


def convert_take(take: Path, image_format: str) -> None:
    """``take``'s JPEGs as another tool leaves them: with EXIF marking them as a quarter turn (a phone held
    upright), or converted to BMPs, TIFFs (one tagged as a quarter turn as ``tiff-turned``) or WebPs (the journal
    naming those)."""
    suffix = SUFFIXES.get(image_format, image_format)
    for path in take.glob("images/*/*.jpg"):
        if image_format == "jpg+exif":
            path.write_bytes(with_exif(path.read_bytes(), "jpg"))
        else:
            path.with_suffix(f".{suffix}").write_bytes(encoded_as(cv2.imread(str(path)), image_format))
            path.unlink()
    if image_format != "jpg+exif":
        (take / FRAMES).write_text((take / FRAMES).read_text().replace(".jpg", f".{suffix}"))


@pytest.mark.parametrize("image_format", ["jpg+exif", "bmp", "tiff", "tiff-turned", "webp"])
def test_a_take_another_tool_wrote_opens_without_decoding_and_plays_as_stored(tmp_path, monkeypatch, image_format):
    """Measured from the headers at open (no decode), each frame delivered at the rig's size. Before, each image
    was decoded at every open: an EXIF one turned by OpenCV (30x40), and the take refused for its size; and (in
    session 62) a TIFF tagged as a quarter turn, decoded at open and refused for its size too."""
    take = write_take(tmp_path / "take", "jpg", frames=5)
    convert_take(take, image_format)
    decoded = []
    monkeypatch.setattr(recording_format, "load_image", lambda path: decoded.append(path) or load_image(path))
    with open_rig(f"replay://{take}?speed=free&policy=all") as source:
        assert decoded == []
        assert [frame.image.shape for frame in source.read(timeout_s=1.0).frames] == [(HEIGHT, WIDTH, 3)] * 2
    assert play(take) == (5, [])


def encoded_as(image: np.ndarray, image_format: str) -> bytes:
    """``image`` in a format of the recorder's, one with EXIF before its frame header, a BMP, a TIFF (LZW, as
    OpenCV writes it; big-endian BigTIFF as ``bigtiff``; tagged as a quarter turn as ``tiff-turned``) or a WebP
    (lossy; lossless as ``webp-lossless``)."""
    if image_format == "bmp":
        return bmp(image)
    if image_format == "tiff":
        return cv2.imencode(".tiff", image)[1].tobytes()
    if image_format == "bigtiff":
        return tiff_laid_out(cv2.imencode(".tiff", image)[1].tobytes(), ">", big=True)
    if image_format == "tiff-turned":  # its Orientation a quarter turn, as a camera held upright may tag it
        return tiff_laid_out(cv2.imencode(".tiff", image)[1].tobytes(), changed={274: (3, (6,))})
    if image_format.startswith("webp"):
        return cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 101 if "lossless" in image_format else 90]
                            )[1].tobytes()
    if image_format == "jpg+exif":
        return with_exif(encode_image(image, "jpg", 90), "jpg")
    return encode_image(image, image_format, 90)


@pytest.mark.parametrize("image_format",
                         [*sorted(IMAGE_FORMATS), "jpg+exif", "bmp", "tiff", "bigtiff", "tiff-turned", "webp",
                          "webp-lossless"])
def test_a_header_cut_anywhere_or_corrupt_never_raises_and_never_gives_a_size_opencv_would_not(tmp_path, image_format):
    """Every cut of the first 200 bytes (and the last 200 of a TIFF, where OpenCV writes its directory), and each
    byte of them set to 0x00 or 0xFF: no exception, and any size read is the size OpenCV decodes (where it decodes,
    as load_image does). A PNG's IHDR is checked against its CRC."""
    data = encoded_as(np.random.default_rng(2).integers(0, 256, (30, 40, 3), np.uint8), image_format)
    places = [*range(200), *(range(len(data) - 200, len(data)) if "tiff" in image_format else ())]  # its IFD last
    damaged = [data[:n] for n in places]
    damaged += [data[:i] + bytes([value]) + data[i + 1:] for i in places for value in (0x00, 0xFF)]
    path = tmp_path / "image"
    for content in damaged:
        path.write_bytes(content)
        size = header_size(path)
        if size is not None:
            try:
                decoded = load_image(path)
            except RigOperationError:
                continue
            assert size == (decoded.shape[1], decoded.shape[0])
    assert header_size(tmp_path / "missing.png") is None


def avif_of(image: np.ndarray, properties: list[bytes]) -> bytes:
    """``image`` as a lossless AVIF (OpenCV's) with rotate or mirror ``properties`` added to its item."""
    return avif_with_properties(cv2.imencode(".avif", image, [cv2.IMWRITE_AVIF_QUALITY, 100])[1].tobytes(), properties)


def turning_properties(data: bytes) -> list[tuple[bytes, int]]:
    """The rotate and mirror property boxes of an AVIF built by ``avif_with_properties`` that turn its image: (type,
    value) of each ``imir``, and of each ``irot`` of an angle other than 0."""
    meta = isobmff_boxes(data, 0, len(data))[b"meta"]
    iprp = isobmff_boxes(data, meta[0] + 12, meta[0] + meta[1])[b"iprp"]
    at, size = isobmff_boxes(data, iprp[0] + 8, iprp[0] + iprp[1])[b"ipco"]
    found, box = [], at + 8
    while box < at + size:
        length, kind = struct.unpack_from(">I4s", data, box)
        if kind == b"imir" or (kind == b"irot" and data[box + 8] & 3):
            found.append((kind, data[box + 8]))
        box += length
    return found


AVIF_TURNS = {"a quarter turn": [avif_transform(b"irot", 1)], "half a turn": [avif_transform(b"irot", 2)],
              "three quarters": [avif_transform(b"irot", 3)], "mirrored": [avif_transform(b"imir", 0)],
              "flipped": [avif_transform(b"imir", 1)],
              "turned and mirrored": [avif_transform(b"irot", 1), avif_transform(b"imir", 1)]}


@pytest.mark.parametrize("turn", sorted(AVIF_TURNS))
def test_an_avif_s_rotate_and_mirror_properties_are_not_handed_to_the_decoder(tmp_path, monkeypatch, turn):
    """An AVIF's irot and imir are a display hint, as a JPEG's EXIF orientation is: its frame is delivered as
    stored. OpenCV 5.0 applies neither; the bytes handed to it say "no turn" (each irot of angle 0, each imir made
    one), so a decoder that applied them would deliver the stored pixels too. Before session 63 the file's bytes
    went to the decoder as they were."""
    image = np.random.default_rng(12).integers(0, 256, (HEIGHT, WIDTH, 3), np.uint8)
    stored = cv2.imdecode(np.frombuffer(avif_of(image, []), np.uint8), cv2.IMREAD_COLOR)
    path = tmp_path / "image.avif"
    path.write_bytes(avif_of(image, AVIF_TURNS[turn]))
    assert turning_properties(path.read_bytes()) != []
    handed = []
    real_imdecode = cv2.imdecode
    monkeypatch.setattr(image_files.cv2, "imdecode", lambda data, flags: handed.append(data.tobytes())
                        or real_imdecode(data, flags))
    assert np.array_equal(load_image(path), stored)
    assert [turning_properties(data) for data in handed] == [[]]
    assert image_size(path) == (WIDTH, HEIGHT)


def test_an_avif_without_a_turn_is_handed_to_the_decoder_as_it_is(tmp_path, monkeypatch):
    """An irot of angle 0, or no property at all: nothing to reset, no copy."""
    image = np.random.default_rng(13).integers(0, 256, (HEIGHT, WIDTH, 3), np.uint8)
    path = tmp_path / "image.avif"
    real_imdecode, handed = cv2.imdecode, []
    monkeypatch.setattr(image_files.cv2, "imdecode", lambda data, flags: handed.append(data.tobytes())
                        or real_imdecode(data, flags))
    for properties in ([], [avif_transform(b"irot", 0)]):
        path.write_bytes(avif_of(image, properties))
        load_image(path)
        assert handed.pop() == path.read_bytes()


def test_an_avif_whose_boxes_cannot_be_followed_is_decoded_or_refused_and_raises_nothing_else(tmp_path):
    """Every cut of an AVIF marked as turned up to its meta box's end (the boxes the walk follows), and each of those
    bytes set to 0x00 or 0xFF: decoded, or a corrupt frame (RigOperationError); never another exception."""
    data = avif_of(np.random.default_rng(14).integers(0, 256, (HEIGHT, WIDTH, 3), np.uint8),
                   AVIF_TURNS["turned and mirrored"])
    meta_end = sum(isobmff_boxes(data, 0, len(data))[b"meta"])
    damaged = [data[:n] for n in range(meta_end + 1)]
    damaged += [data[:i] + bytes([value]) + data[i + 1:] for i in range(meta_end) for value in (0x00, 0xFF)]
    path, decoded = tmp_path / "image.avif", 0
    for content in damaged:
        path.write_bytes(content)
        try:
            load_image(path)
            decoded += 1
        except RigOperationError:
            continue
    assert decoded > 0


def test_a_take_of_avifs_marked_as_turned_opens_and_plays_as_stored(tmp_path):
    """Each frame's size is decoded at open (no AVIF header reader), as stored: the rig's, not turned."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    for path in take.glob("images/*/*.jpg"):
        path.with_suffix(".avif").write_bytes(avif_of(cv2.imread(str(path)), AVIF_TURNS["turned and mirrored"]))
        path.unlink()
    (take / FRAMES).write_text((take / FRAMES).read_text().replace(".jpg", ".avif"))
    assert play(take) == (3, [])


def clean_aperture(width: int, height: int, offset: tuple[int, int]) -> bytes:
    """An AVIF ``clap`` property box: a crop of ``width`` x ``height`` pixels, its centre ``offset`` from the
    image's (each a fraction of 1)."""
    return struct.pack(">I4s8i", 40, b"clap", width, 1, height, 1, offset[0], 1, offset[1], 1)


@pytest.mark.parametrize("offset", [(0, 0), (-10, -7)])
def test_an_avif_s_clean_aperture_is_not_applied_the_stored_image_is_read_and_measured(tmp_path, offset):
    """OpenCV 5.0 (libavif) decodes the whole stored image, a ``clap`` crop ignored: the size measured at open is
    the decoded one (no AVIF header reader), so a decoder applying it would change both, and a crop of another size
    than the rig's would be refused at open, not misread (avif_header's docstring)."""
    image = np.random.default_rng(15).integers(0, 256, (HEIGHT, WIDTH, 3), np.uint8)
    plain = cv2.imencode(".avif", image, [cv2.IMWRITE_AVIF_QUALITY, 100])[1].tobytes()
    path = tmp_path / "image.avif"
    path.write_bytes(avif_with_properties(plain, [clean_aperture(20, 16, offset)]))
    assert image_size(path) == (WIDTH, HEIGHT)
    assert np.array_equal(load_image(path), cv2.imdecode(np.frombuffer(plain, np.uint8), cv2.IMREAD_COLOR))


def test_a_multi_page_tiff_is_read_and_measured_from_its_first_page_whatever_its_later_pages_hold(tmp_path):
    """OpenCV decodes a TIFF's first page (cv2.imread and cv2.imdecode alike), the page whose directory the header
    reader, the turn reset and the cut-short check read; a later page of another size, or cut short, changes
    nothing (tiff_header's docstring)."""
    first = np.random.default_rng(16).integers(0, 256, (HEIGHT, WIDTH, 3), np.uint8)
    path = tmp_path / "image.tiff"
    assert cv2.imwritemulti(str(path), [first, np.zeros((2 * HEIGHT, 2 * WIDTH, 3), np.uint8)])
    data = path.read_bytes()
    for content in (data, data[:-10]):  # whole, then cut in its last page's directory
        path.write_bytes(content)
        assert header_size(path) == (WIDTH, HEIGHT) == image_size(path)
        assert recording_format.payload_is_whole(path)
        assert np.array_equal(load_image(path), first)


def retiled(take: Path, tile: tuple[int, int]) -> list[Path]:
    """``take``'s JPEGs as uncompressed tiled TIFFs of ``tile`` (the journal naming those), in recorded order."""
    tiffs = []
    for path in sorted(take.glob("images/*/*.jpg")):
        tiffs.append(path.with_suffix(".tiff"))
        tiffs[-1].write_bytes(tiff_tiled(cv2.imread(str(path)), tile))
        path.unlink()
    (take / FRAMES).write_text((take / FRAMES).read_text().replace(".jpg", ".tiff"))
    return tiffs


@pytest.mark.parametrize(("tile", "samples", "separate"),
                         [((16, 16), 3, False), ((48, 32), 3, False), ((16, 32), 1, False), ((16, 16), 3, True)])
def test_a_valid_tiled_tiff_opencv_refuses_from_memory_is_no_header_size_and_is_read_from_the_file(
        tmp_path, monkeypatch, tile, samples, separate):
    """Uncompressed tiles of a byte size not a multiple of 1024 (a sample a tile where the samples are in separate
    planes): cv2.imread of the file decodes it as it is (the file is valid), cv2.imdecode (load_image) does not
    ('Invalid tile byte count'). Before, its header gave a size (the take opened, then every frame was 'corrupt');
    then (session 63) the take was refused. Read through OpenCV's file reader, it plays; the cause is named only
    where that fails too."""
    image = np.random.default_rng(12).integers(0, 256, (30, 40, samples)[:2 + (samples > 1)], np.uint8)
    path = tmp_path / "image.tiff"
    path.write_bytes(tiff_tiled(image, tile, separate_planes=separate))
    assert np.array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), image)
    assert cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR) is None
    assert header_size(path) is None
    assert np.array_equal(load_image(path), cv2.imread(str(path), cv2.IMREAD_COLOR))
    assert image_size(path) == (40, 30)
    path.write_bytes(turned_tiff(path.read_bytes()))  # the file reader is not used: its Orientation is reset in memory
    with pytest.raises(recording_format.RefusedLayoutError,
                       match=r"image\.tiff does not decode: it is an uncompressed tiled TIFF .*Invalid tile byte count"
                             r".*file reader.*not used for it: its orientation"):
        load_image(path)
    assert isinstance(image_size(path), recording_format.RefusedLayoutError)


def turned_tiff(data: bytes) -> bytes:
    """A TIFF's bytes with Orientation 3 (half a turn): replay decodes it from memory, its tag reset there."""
    return tiff_laid_out(data, changed={274: (3, (3,))})


def tiles_past_the_end(path: Path) -> None:
    """A tiled TIFF corrupted in place: its header intact, its tiles' offsets past the end of the file."""
    data = path.read_bytes()
    kind, offsets = tiff_entries(data)[324]
    path.write_bytes(tiff_laid_out(data, changed={324: (kind, tuple(o + len(data) for o in offsets))}))


def test_a_corrupt_tiled_tiff_of_a_layout_opencv_refuses_from_memory_is_corrupt_not_a_refused_layout(tmp_path):
    """Both OpenCV readers fail on it: its file reader was used, so the file is corrupt. It was called valid (the
    layout's refusal, 'though the file is valid'), and its take refused at open."""
    path = tmp_path / "image.tiff"
    path.write_bytes(tiff_tiled(np.zeros((30, 40, 3), np.uint8), (16, 16)))
    tiles_past_the_end(path)
    assert cv2.imread(str(path)) is None
    with pytest.raises(RigOperationError, match=r"image\.tiff is corrupt \(OpenCV cannot decode it, from memory nor "
                                                r"through its file reader\)") as caught:
        load_image(path)
    assert not isinstance(caught.value, recording_format.RefusedLayoutError)
    assert image_size(path) is None


@pytest.mark.parametrize(("tile", "samples", "separate"),
                         [((32, 32), 3, False), ((16, 16), 4, False), ((16, 64), 1, False), ((32, 32), 3, True)])
def test_a_tiled_tiff_of_tiles_of_a_multiple_of_1024_bytes_is_measured_from_its_header(tmp_path, no_decode, tile,
                                                                                        samples, separate):
    image = np.random.default_rng(13).integers(0, 256, (30, 40, samples)[:2 + (samples > 1)], np.uint8)
    path = tmp_path / "image.tiff"
    path.write_bytes(tiff_tiled(image, tile, separate_planes=separate))
    assert header_size(path) == (40, 30) == image_size(path)
    assert np.array_equal(load_image(path), cv2.imread(str(path), cv2.IMREAD_COLOR))


def test_a_take_of_tiled_tiffs_opencv_refuses_from_memory_plays(tmp_path):
    """Refused at open in session 63 (every frame would have been corrupt): read from the file, each decodes."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    retiled(take, (16, 16))
    assert play(take) == (3, [])


def test_a_take_of_tiled_tiffs_no_reader_decodes_is_refused_at_open_naming_the_file_and_the_cause(tmp_path):
    """Where the file reader is not used either (an Orientation to reset, in memory), none of a camera's images
    decode, and the take is refused at open: before session 63 it opened (each size read from its header) and
    every read was a corrupt frame: nothing played, and nothing said why."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    tiffs = retiled(take, (16, 16))
    for path in tiffs:
        path.write_bytes(turned_tiff(path.read_bytes()))
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(RigInitializationError,
                       match=rf"camera 'left': none of its 3 images decode.*3 of a layout this OpenCV refuses; first: "
                             rf"recording image {re.escape(str(tiffs[0]))}.*768 bytes, not a multiple of 1024"
                             rf".*Invalid tile.*orientation"):
        source.open()
    assert isinstance(source.size_error(), recording_format.UndecodableImageError)


@pytest.mark.parametrize("damage", [tiles_past_the_end, lambda path: path.write_bytes(turned_tiff(path.read_bytes()))],
                         ids=["corrupt", "valid, not decoded"])
def test_a_take_with_one_tiled_tiff_no_reader_decodes_plays_it_as_a_corrupt_frame(tmp_path, damage):
    """One file of a layout OpenCV refuses from memory that does not decode, corrupt or valid: its frame is a
    corrupt frame, as any other, its read naming the file (the next read goes on). The whole take was refused at
    open (UndecodableImageError, calling a corrupt file valid)."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    bad = retiled(take, (16, 16))[2]
    damage(bad)
    pairs, errors = play(take)
    assert pairs == 2 and len(errors) == 1
    assert str(bad) in str(errors[0]) and not isinstance(errors[0], RigInitializationError)


def test_a_take_one_camera_of_which_is_float_tiffs_is_refused_at_open_naming_their_samples(tmp_path):
    """Valid TIFFs of float samples, which do not decode to 8 bits: the take was refused at open calling the first
    file corrupt (a RigInitializationError); since session 66 it names their samples, an UndecodableImageError."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    floats = []
    for path in sorted(take.glob("images/left/*.jpg")):
        floats.append(path.with_suffix(".tiff"))
        assert cv2.imwrite(str(floats[-1]), cv2.imread(str(path)).astype(np.float32) / 255)
        path.unlink()
    journal = take / FRAMES
    journal.write_text("".join(line.replace(".jpg", ".tiff") if '"left"' in line else line
                               for line in journal.read_text().splitlines(keepends=True)))
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(RigInitializationError,
                       match=rf"camera 'left': none of its 3 images decode.*3 of a layout this OpenCV refuses; first: "
                             rf"recording image {re.escape(str(floats[0]))} does not decode: it has float32 samples"):
        source.open()
    assert isinstance(source.size_error(), recording_format.UndecodableImageError)


def test_a_take_whose_tiled_tiffs_are_all_corrupt_is_refused_at_open_naming_one_as_corrupt(tmp_path):
    """Nothing of it would play: refused at open, as a take of valid images no reader decodes is, but the file
    called corrupt (it was called valid, the remedy a rewrite of its tiles)."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    tiffs = retiled(take, (16, 16))
    for path in tiffs:
        tiles_past_the_end(path)
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(RigInitializationError, match=rf"camera 'left': none of its 3 images decode, nothing of it "
                                                     rf"would play \(first: {re.escape(str(tiffs[0]))} is corrupt"):
        source.open()
    assert not isinstance(source.size_error(), recording_format.UndecodableImageError)


def test_a_take_one_camera_of_which_has_no_image_that_decodes_is_refused_at_open(tmp_path):
    """Every image of camera 'right' garbage (no header to read, nothing decodes): no pair would ever play. It
    opened, and every read was a corrupt frame (a daemon reopened it for ever); one such image is still a
    corrupt frame (test_a_take_with_one_tiled_tiff_no_reader_decodes_plays_it_as_a_corrupt_frame)."""
    take = write_take(tmp_path / "take", "png", frames=3)
    for n in range(3):
        image_of(take, "right", n).write_bytes(b"not an image at all")
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(RigInitializationError, match=rf"camera 'right': none of its 3 images decode, nothing of it "
                                                     rf"would play \(first: {re.escape(str(image_of(take, 'right', 0)))} "
                                                     rf"is corrupt"):
        source.open()


def test_a_take_of_tiled_tiffs_opencv_decodes_opens_and_plays(tmp_path):
    take = write_take(tmp_path / "take", "jpg", frames=3)
    retiled(take, (32, 32))
    assert play(take) == (3, [])


# ------------------------------------------------------------------ a TIFF's compression
def recompressed(take: Path, compression: int) -> list[Path]:
    """``take``'s JPEGs as uncompressed TIFFs (OpenCV's) whose Compression says ``compression`` (the journal naming
    those), in recorded order: a JPEG 2000 TIFF's header, say, with data OpenCV will not get to."""
    tiffs = []
    for path in sorted(take.glob("images/*/*.jpg")):
        data = cv2.imencode(".tiff", cv2.imread(str(path)), [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
        tiffs.append(path.with_suffix(".tiff"))
        tiffs[-1].write_bytes(tiff_laid_out(data, changed={259: (3, (compression,))}))
        path.unlink()
    (take / FRAMES).write_text((take / FRAMES).read_text().replace(".jpg", ".tiff"))
    return tiffs


@pytest.mark.parametrize(("compression", "name"), [(34712, "JPEG 2000"), (65000, "unregistered"), (50000, "Zstandard")])
def test_a_tiff_of_a_compression_opencv_does_not_decode_is_a_frame_naming_it_not_a_black_image(tmp_path, capfd,
                                                                                              compression, name):
    """OpenCV read a JPEG 2000 TIFF (34712, or any value libtiff has no codec for) as an image of zeros of its
    stored size, libtiff's error only logged: the frame was delivered black, measured at open by that decode. Its
    read names the file and the compression (a valid image this OpenCV refuses), and it has no size; a Zstandard
    one (None from OpenCV already) was 'corrupt'."""
    path = tmp_path / "image.tiff"
    data = cv2.imencode(".tiff", np.full((HEIGHT, WIDTH, 3), 200, np.uint8), [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1]
    path.write_bytes(tiff_laid_out(data.tobytes(), changed={259: (3, (compression,))}))
    said = (f"recording image {path} does not decode: it is a TIFF of Compression {compression} ({name}), which "
            f"OpenCV {cv2.__version__}'s libtiff does not decode")
    with pytest.raises(recording_format.RefusedLayoutError, match=re.escape(said)):
        load_image(path)
    assert header_size(path) is None
    assert isinstance(image_size(path), recording_format.RefusedLayoutError)
    captured = capfd.readouterr()
    assert "TIFF" not in captured.err + captured.out  # nothing decoded: libtiff says nothing


@pytest.mark.parametrize(("chain_step", "error_type", "verb", "text"), [
    ("tiff_compression_refusal", recording_format.RefusedLayoutError, "does not decode", "it is a new layout"),
    ("tiff_data_refusal", RigOperationError, "is corrupt", "a new cause"),
])
def test_load_image_names_the_cause_the_shared_chain_gives(tmp_path, monkeypatch, chain_step, error_type, verb,
                                                           text):
    """load_image repeated image_files' chain of causes with its own calls (compression, strips, samples), so a
    cause added to the chain reached ghnerf-run, ghcal and the ZJU-MoCap reader but not replay: a step of the chain
    changed (here, to name a corrupt PNG) now reaches load_image too, typed by its kind."""
    path = tmp_path / "image.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n cut")
    with pytest.raises(RigOperationError, match=re.escape(f"recording image {path} is corrupt (OpenCV cannot")):
        load_image(path)
    monkeypatch.setattr(image_files, chain_step, lambda p: text.removeprefix("it is "))
    with pytest.raises(error_type) as info:
        load_image(path)
    assert type(info.value) is error_type and str(info.value) == f"recording image {path} {verb}: {text}"
    assert image_files.unread_because(path, cv2.IMREAD_COLOR) == text


def test_a_take_with_one_jpeg_2000_tiff_plays_it_as_a_corrupt_frame_naming_the_compression(tmp_path):
    """It played as a black frame, estimated as any other; now its read fails, naming the file and the
    compression, and the next read goes on."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    tiffs = recompressed(take, 1)  # uncompressed: they play
    tiffs[2].write_bytes(tiff_laid_out(tiffs[2].read_bytes(), changed={259: (3, (34712,))}))
    pairs, errors = play(take)
    assert pairs == 2 and len(errors) == 1
    assert str(tiffs[2]) in str(errors[0]) and "Compression 34712 (JPEG 2000)" in str(errors[0])
    assert not isinstance(errors[0], RigInitializationError)


def test_a_take_of_jpeg_2000_tiffs_is_refused_at_open_naming_the_file_and_the_compression(tmp_path):
    """Nothing of it would play: refused at open (it opened, measured by decodes of zeros, and played black)."""
    take = write_take(tmp_path / "take", "jpg", frames=3)
    tiffs = recompressed(take, 34712)
    source = create_rig_source(f"replay://{take}?speed=free")
    with pytest.raises(recording_format.UndecodableImageError,
                       match=rf"camera 'left': none of its 3 images decode.*first: recording image "
                             rf"{re.escape(str(tiffs[0]))} does not decode: it is a TIFF of Compression 34712 "
                             rf"\(JPEG 2000\)"):
        source.open()


@pytest.mark.parametrize("dtype", [np.int8, np.int16])
def test_signed_8_or_16_bit_samples_are_not_named_as_the_cause(tmp_path, dtype):
    """OpenCV decodes int8 and int16 TIFF samples to 8 bits, as it does uint8 and uint16: a file of them that failed
    its first decode for another reason was said to have "int16 samples (...): only 8- or 16-bit images decode"."""
    path = tmp_path / "image.tiff"
    assert cv2.imwrite(str(path), np.full((6, 8, 3), 5, dtype))
    assert cv2.imread(str(path), cv2.IMREAD_COLOR) is not None  # they decode: no cause of a failed one
    assert image_files.samples_not_8_bit(path) is None
