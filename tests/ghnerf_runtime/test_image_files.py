"""ghnerf_runtime.image_files reads an image's pixels as stored, whatever orientation its file is tagged with: EXIF in
a JPEG, PNG or WebP (OpenCV ignores it given IMREAD_IGNORE_ORIENTATION), and a TIFF's own Orientation tag (OpenCV's
TIFF decoder turns the image by it whatever the flags: the tag is set to 1 in a copy of the bytes first), and an
AVIF's rotate and mirror properties (made "no turn" in a copy the same way, though OpenCV 5.0 applies neither)."""
import builtins
import io
import os
import struct

import cv2
import numpy as np
import pytest

from ghnerf_runtime import avif_header, image_files, tiff_compression, tiff_header
from ghnerf_runtime.image_files import AS_STORED, decode_image_or_none, read_image_or_none
from tests.exif_images import exif_orientation, jpeg_turned, png_turned
from tests.odd_images import (
    STRIPS_IMAGE,
    avif_transform,
    avif_with_properties,
    riff_chunk,
    tiff_entries,
    tiff_laid_out,
    tiff_tiled,
    tiff_with_strip_count,
    webp_extended,
)

#: 7 wide, 5 high: a transpose changes the shape, a flip the pixels (random, so no flip leaves them as they were).
STORED_SHAPE = (5, 7)
ORIENTATIONS = range(1, 9)
#: The flags the project reads images with: replay's and ghnerf-run's, ghcal's board views, ZJU masks.
READ_FLAGS = {"colour": cv2.IMREAD_COLOR, "grey": cv2.IMREAD_GRAYSCALE, "unchanged": cv2.IMREAD_UNCHANGED,
              "grey-any-depth": cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH}


def shown(stored: np.ndarray, orientation: int) -> np.ndarray:
    """How a viewer shows ``stored`` pixels tagged with ``orientation`` (TIFF 6.0 / EXIF: 2 mirrored, 3 half a
    turn, 4 flipped, 5 transposed, 6 a quarter clockwise, 7 transposed the other way, 8 a quarter anticlockwise)."""
    turns = {1: lambda a: a, 2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
             5: lambda a: a.swapaxes(0, 1), 6: lambda a: np.rot90(a, -1), 7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
             8: lambda a: np.rot90(a, 1)}
    return turns[orientation](stored)


def stored_image(channels: int, dtype=np.uint8) -> np.ndarray:
    rng = np.random.default_rng(channels)
    shape = STORED_SHAPE if channels == 1 else (*STORED_SHAPE, channels)
    return rng.integers(0, np.iinfo(dtype).max, shape, dtype, endpoint=True)


def tagged_tiff(image: np.ndarray, orientation: int, order: str = "<", big: bool = False, kind: int = 3) -> bytes:
    """``image`` as a TIFF (OpenCV's, LZW) laid out in ``order``, BigTIFF where ``big``, its Orientation
    ``orientation`` of entry type ``kind`` (3 SHORT, 4 LONG, 16 LONG8)."""
    data = cv2.imencode(".tiff", image)[1].tobytes()
    return tiff_laid_out(data, order, big, {274: (kind, (orientation,))})


def as_array(data: bytes) -> np.ndarray:
    return np.frombuffer(data, np.uint8)


def decoded_as_written(image: np.ndarray, flags: int) -> np.ndarray:
    """What OpenCV gives for ``image`` written as an untagged TIFF and read with ``flags``: the stored pixels."""
    return cv2.imdecode(cv2.imencode(".tiff", image)[1], flags)


# ------------------------------------------------------------------ what OpenCV does
@pytest.mark.parametrize("flags", READ_FLAGS.values(), ids=READ_FLAGS.keys())
@pytest.mark.parametrize("channels", [1, 3])
def test_opencv_turns_a_tiff_by_its_orientation_tag_whatever_the_flags(flags, channels):
    """The reason for the reset (docs/recording-format.md, "Images"): OpenCV 5.0's TIFF decoder shows the image as
    its tag says, IMREAD_IGNORE_ORIENTATION and IMREAD_UNCHANGED included. Should an OpenCV release stop turning
    it, this fails while image_files still reads the stored pixels (its reset does not rely on the turn): the docs'
    caveat is then to be dated."""
    image = stored_image(channels)
    stored = decoded_as_written(image, flags | AS_STORED)
    for orientation in ORIENTATIONS:
        opencv = cv2.imdecode(as_array(tagged_tiff(image, orientation)), flags | AS_STORED)
        assert np.array_equal(opencv, shown(stored, orientation)), orientation


def exif_tagged(image: np.ndarray, fmt: str, orientation: int) -> bytes:
    """``image`` (lossless where the format allows) with an EXIF orientation, placed as a phone or tool writes it."""
    if fmt == "png":
        return png_turned(cv2.imencode(".png", image)[1].tobytes(), orientation)
    if fmt == "webp":
        data = cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 101])[1].tobytes()
        return webp_extended(data, flags=0x08, after=riff_chunk(b"EXIF", exif_orientation(orientation)))
    return jpeg_turned(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 100])[1].tobytes(), orientation)


@pytest.mark.parametrize("fmt", ["jpg", "png", "webp"])
def test_opencv_ignores_a_jpeg_s_png_s_or_webp_s_exif_orientation_as_asked(fmt):
    """The formats whose orientation is EXIF: IMREAD_IGNORE_ORIENTATION keeps their stored pixels (the default
    flags turn them as the tag says), so AS_STORED alone reads them as stored."""
    image = stored_image(3)
    upright = cv2.imdecode(as_array(exif_tagged(image, fmt, 1)), cv2.IMREAD_COLOR)
    for orientation in ORIENTATIONS:
        data = as_array(exif_tagged(image, fmt, orientation))
        assert np.array_equal(cv2.imdecode(data, cv2.IMREAD_COLOR | AS_STORED), upright), orientation
        assert np.array_equal(cv2.imdecode(data, cv2.IMREAD_COLOR), shown(upright, orientation)), orientation


# ------------------------------------------------------------------ what image_files reads
@pytest.mark.parametrize("flags", READ_FLAGS.values(), ids=READ_FLAGS.keys())
@pytest.mark.parametrize(("channels", "dtype"), [(1, np.uint8), (3, np.uint8), (4, np.uint8), (1, np.uint16),
                                                 (3, np.uint16)])
def test_a_tiff_tagged_with_any_orientation_is_read_and_decoded_as_stored(tmp_path, flags, channels, dtype):
    image = stored_image(channels, dtype)
    stored = decoded_as_written(image, flags)
    path = tmp_path / "view.tiff"
    for orientation in ORIENTATIONS:
        path.write_bytes(tagged_tiff(image, orientation))
        assert np.array_equal(read_image_or_none(path, flags), stored), orientation
        assert np.array_equal(decode_image_or_none(np.fromfile(path, np.uint8), flags), stored), orientation


@pytest.mark.parametrize(("order", "big", "kind"), [("<", False, 4), (">", False, 3), (">", False, 4),
                                                    ("<", True, 3), (">", True, 4)],
                         ids=["classic-long", "big-endian-short", "big-endian-long", "bigtiff-short", "bigtiff-long"])
def test_a_tagged_tiff_of_either_byte_order_classic_or_big_is_read_as_stored(tmp_path, order, big, kind):
    """OpenCV turns by a LONG Orientation as by a SHORT one (the type TIFF gives it): both are reset, in the
    file's byte order and the entry's width."""
    image = stored_image(3)
    path = tmp_path / "view.tif"
    for orientation in ORIENTATIONS:
        path.write_bytes(tagged_tiff(image, orientation, order, big, kind))
        assert np.array_equal(read_image_or_none(path, cv2.IMREAD_UNCHANGED), image), orientation


def test_reading_a_tagged_tiff_leaves_its_file_as_it_was(tmp_path):
    """The tag is set to 1 in a copy of the bytes, never in the user's file (nor in the array handed in)."""
    data = tagged_tiff(stored_image(3), 6)
    path = tmp_path / "view.tiff"
    path.write_bytes(data)
    handed_in = as_array(data).copy()
    read_image_or_none(path, cv2.IMREAD_COLOR)
    decode_image_or_none(handed_in, cv2.IMREAD_COLOR)
    assert path.read_bytes() == data and handed_in.tobytes() == data


def test_only_a_tiff_s_single_orientation_other_than_1_is_reset(tmp_path):
    """Nothing to reset: not a TIFF, a TIFF without the tag (as OpenCV writes one) or upright, or tagged with two
    values (libtiff ignores such a tag: OpenCV decodes the stored pixels)."""
    image = stored_image(3)
    plain = cv2.imencode(".tiff", image)[1].tobytes()
    path = tmp_path / "view.tiff"
    cases = {"png": cv2.imencode(".png", image)[1].tobytes(), "untagged": plain, "upright": tagged_tiff(image, 1),
             "two values": tiff_laid_out(plain, changed={274: (3, (6, 6))})}
    for name, data in cases.items():
        path.write_bytes(data)
        with open(path, "rb") as f:
            assert tiff_header.orientation_reset(f) is None, name
        assert np.array_equal(read_image_or_none(path, cv2.IMREAD_UNCHANGED), image), name


def test_a_file_that_cannot_be_read_or_decoded_is_still_none(tmp_path):
    """A missing file, and a TIFF tagged to be turned cut short: its header only, its directory past its end."""
    path = tmp_path / "view.tiff"
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    cut = tagged_tiff(stored_image(3), 6)[:8]
    path.write_bytes(cut)
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    assert decode_image_or_none(as_array(cut), cv2.IMREAD_COLOR) is None


def test_an_avif_s_rotate_and_mirror_properties_never_reach_the_decoder_whichever_reader(tmp_path, monkeypatch):
    """A file read by its path (ghnerf-run's stills, ghcal's views) as by its bytes (replay): the decoder is handed
    an irot of angle 0 where the file has an irot of a quarter turn and an imir, and the user's file is left as it
    was. Before session 63 cv2.imread read the file as it was."""
    image = stored_image(3)
    plain = cv2.imencode(".avif", image, [cv2.IMWRITE_AVIF_QUALITY, 100])[1].tobytes()
    data = avif_with_properties(plain, [avif_transform(b"irot", 1), avif_transform(b"imir", 0)])
    path = tmp_path / "view.avif"
    path.write_bytes(data)
    handed = []
    real_imdecode, real_imread = cv2.imdecode, cv2.imread
    monkeypatch.setattr(image_files.cv2, "imdecode", lambda buf, flags: handed.append(buf.tobytes())
                        or real_imdecode(buf, flags))
    monkeypatch.setattr(image_files.cv2, "imread", lambda name, flags: handed.append(open(name, "rb").read())
                        or real_imread(name, flags))
    expected = real_imdecode(as_array(plain), cv2.IMREAD_COLOR)
    assert np.array_equal(read_image_or_none(path, cv2.IMREAD_COLOR), expected)
    assert np.array_equal(decode_image_or_none(as_array(data), cv2.IMREAD_COLOR), expected)
    no_turn = avif_with_properties(plain, [avif_transform(b"irot", 1), avif_transform(b"irot", 0)])
    no_turn = no_turn.replace(avif_transform(b"irot", 1), avif_transform(b"irot", 0), 1)
    assert handed == [no_turn, no_turn] and path.read_bytes() == data
    with open(path, "rb") as f:
        resets = avif_header.transforms_reset(f)
    assert resets == [(data.index(b"irot"), b"irot\x00"), (data.index(b"imir"), b"irot\x00")]


@pytest.mark.parametrize("kind", ["jpg", "png", "tiff", "tagged-tiff", "turned-avif"])
def test_a_read_opens_the_file_once_whatever_its_format(tmp_path, monkeypatch, kind):
    """One open of the file serves the TIFF sample check, the turn resets and (where the bytes are decoded from
    memory) the read of the rest; cv2.imread's own C-level open, for a file needing no reset, is not Python's.
    Before session 63's change a read opened it two (JPEG, PNG, plain TIFF) or three times (a tagged TIFF, a
    turned AVIF), and gave the same pixels."""
    image = stored_image(3)
    if kind == "tagged-tiff":
        data = tagged_tiff(image, 6)
    elif kind == "turned-avif":
        plain = cv2.imencode(".avif", image, [cv2.IMWRITE_AVIF_QUALITY, 100])[1].tobytes()
        data = avif_with_properties(plain, [avif_transform(b"irot", 1), avif_transform(b"imir", 0)])
    else:
        data = cv2.imencode(f".{kind}", image)[1].tobytes()
    path = tmp_path / f"view.{kind.split('-')[-1]}"
    path.write_bytes(data)
    expected = decode_image_or_none(as_array(data), cv2.IMREAD_COLOR)
    opened = []
    real_open = builtins.open

    def counting_open(file, *args, **kwargs):
        opened.append(os.fspath(file) if isinstance(file, (str, os.PathLike)) else file)
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", counting_open)
    image_read = read_image_or_none(path, cv2.IMREAD_COLOR)
    monkeypatch.undo()
    assert opened.count(str(path)) == 1, opened
    assert image_read is not None and np.array_equal(image_read, expected)


@pytest.mark.parametrize("flags", [cv2.IMREAD_COLOR, cv2.IMREAD_UNCHANGED], ids=["colour", "unchanged"])
def test_a_decode_walks_a_tiff_s_first_directory_once(tmp_path, monkeypatch, flags):
    """Its compression, its sample size and its Orientation are read in one walk of the header: each was a walk of
    its own (three a decode, replay's frames included), reading the same directory."""
    data = tagged_tiff(stored_image(3), 6)
    path = tmp_path / "view.tiff"
    path.write_bytes(data)
    expected = decode_image_or_none(as_array(data), flags)
    walks = []
    real_walk = tiff_header._first_directory_entries

    def counting_walk(f, layout):
        walks.append(layout)
        return real_walk(f, layout)

    monkeypatch.setattr(tiff_header, "_first_directory_entries", counting_walk)
    assert np.array_equal(decode_image_or_none(as_array(data), flags), expected) and len(walks) == 1
    assert np.array_equal(read_image_or_none(path, flags), expected) and len(walks) == 2


def test_a_tiff_tag_the_walk_cannot_read_leaves_the_others_read(tmp_path):
    """One walk reads each tag as a walk of its own did: an Orientation of text (no unsigned integer) leaves the
    Compression judged, and a Compression of text leaves the turn reset."""
    image = stored_image(3)
    plain = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    path = tmp_path / "view.tiff"
    path.write_bytes(tiff_laid_out(plain, changed={259: (3, (34712,)), 274: (2, (54, 0))}))
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    assert decode_image_or_none(as_array(path.read_bytes()), cv2.IMREAD_COLOR) is None
    path.write_bytes(tiff_laid_out(plain, changed={259: (2, (49, 0)), 274: (3, (6,))}))
    with open(path, "rb") as f:
        tags = tiff_header.read_tags(f, frozenset({tiff_header.COMPRESSION, tiff_header.ORIENTATION}))
    with open(path, "rb") as f:
        assert tiff_header.upright_reset(tags) == tiff_header.orientation_reset(f) is not None
    assert tags.get(tiff_header.COMPRESSION) is None


# ------------------------------------------------------------------ a TIFF's compression
#: Compression values OpenCV 5.0 does not decode: JPEG 2000 and an unregistered one (read as images of zeros
#: before session 64's review), LERC and Zstandard (libtiff's codecs this build leaves out: None already).
UNDECODED_COMPRESSIONS = {34712: "JPEG 2000", 65000: "unregistered", 34887: "LERC", 50000: "Zstandard"}


def tiff_of_compression(image: np.ndarray, compression: int, order: str = "<", big: bool = False) -> bytes:
    """``image`` as an uncompressed TIFF (OpenCV's) whose Compression says ``compression``, laid out in ``order``,
    BigTIFF where ``big``: the header of a file compressed so, with data OpenCV will not get to."""
    data = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    return tiff_laid_out(data, order, big, {259: (3, (compression,))})


@pytest.mark.parametrize("compression", UNDECODED_COMPRESSIONS)
@pytest.mark.parametrize("flags", READ_FLAGS.values(), ids=READ_FLAGS.keys())
@pytest.mark.parametrize(("order", "big"), [("<", False), (">", True)], ids=["classic-le", "bigtiff-be"])
def test_a_tiff_of_a_compression_opencv_does_not_decode_is_none_not_an_image_of_zeros(tmp_path, capfd, compression,
                                                                                     flags, order, big):
    """A JPEG 2000 TIFF (another camera tool's) was read as an all-black image by every reader (ghnerf-run
    --images, ghcal's views, replay://), libtiff's "Compression scheme 34712 strip decoding is not implemented"
    only logged: it is None, told from its header (nothing decoded, nothing logged), and the cause is named."""
    path = tmp_path / "view.tiff"
    path.write_bytes(tiff_of_compression(stored_image(3), compression, order, big))
    assert read_image_or_none(path, flags) is None
    assert decode_image_or_none(as_array(path.read_bytes()), flags) is None
    said = f"a TIFF of Compression {compression} ({UNDECODED_COMPRESSIONS[compression]}), which OpenCV"
    assert image_files.tiff_compression_refusal(path).startswith(said)
    captured = capfd.readouterr()
    assert "TIFF" not in captured.err + captured.out


@pytest.mark.parametrize("compression", [1, 5, 7, 8, 32773, 32946])
def test_a_tiff_of_each_compression_opencv_writes_is_read_and_not_refused(tmp_path, compression):
    image = stored_image(3)
    path = tmp_path / "view.tiff"
    assert cv2.imwrite(str(path), image, [cv2.IMWRITE_TIFF_COMPRESSION, compression])
    expected = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert expected is not None and expected.any()
    assert np.array_equal(read_image_or_none(path, cv2.IMREAD_COLOR), expected)
    assert np.array_equal(decode_image_or_none(as_array(path.read_bytes()), cv2.IMREAD_COLOR), expected)
    assert image_files.tiff_compression_refusal(path) is None


def test_only_a_tiff_s_single_compression_value_is_judged(tmp_path):
    """No Compression tag is uncompressed (read); one of several values, libtiff refuses the file (None from
    OpenCV, no refusal named here); another format has none."""
    image = stored_image(3)
    data = cv2.imencode(".tiff", image, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    path = tmp_path / "view.tiff"
    path.write_bytes(tiff_laid_out(data, changed={259: None}))
    assert np.array_equal(read_image_or_none(path, cv2.IMREAD_COLOR), image)
    path.write_bytes(tiff_laid_out(data, changed={259: (3, (34712, 1))}))
    assert image_files.tiff_compression_refusal(path) is None and read_image_or_none(path, cv2.IMREAD_COLOR) is None
    path = tmp_path / "view.png"
    path.write_bytes(cv2.imencode(".png", image)[1].tobytes())
    assert image_files.tiff_compression_refusal(path) is None
    assert image_files.tiff_compression_refusal(tmp_path / "missing.tiff") is None


def test_why_a_read_failed_is_said_for_the_reads_it_concerns(tmp_path):
    """unread_because, every caller's one source of the cause (ghnerf-run, ghcal, the ZJU-MoCap reader): the
    compression for any read, the samples only for a read to 8 bits (IMREAD_ANYDEPTH keeps float32), nothing for a
    corrupt file."""
    jpeg2000 = tmp_path / "view.tiff"
    jpeg2000.write_bytes(tiff_of_compression(stored_image(3), 34712))
    for flags in READ_FLAGS.values():
        assert image_files.unread_because(jpeg2000, flags).startswith("it is a TIFF of Compression 34712 (JPEG 2000)")
    floats = tmp_path / "float.tiff"
    assert cv2.imwrite(str(floats), np.full((6, 8), 0.5, np.float32))
    assert image_files.unread_because(floats, cv2.IMREAD_COLOR).startswith("it has float32 samples (8x6, 1 channel)")
    assert image_files.unread_because(floats, cv2.IMREAD_ANYDEPTH) is None
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n cut")
    assert image_files.unread_because(corrupt, cv2.IMREAD_COLOR) is None


@pytest.mark.parametrize("kind", ["plain", "turned", "name_not_utf8"])
def test_the_read_and_its_reason_take_the_one_choice_of_reader(tmp_path, monkeypatch, kind):
    """``decoded_from_memory_because`` re-derived the read's choice between the bytes and OpenCV's file reader: had
    the two drifted apart, replay would call a valid file corrupt. Both now ask ``_memory_decode_because``: the read
    goes to the file reader exactly where no reason is given, and follows the choice where it is changed."""
    image = stored_image(3)
    data = tagged_tiff(image, 3) if kind == "turned" else tagged_tiff(image, 1)
    name = os.fsdecode(b"frame\xff.tiff") if kind == "name_not_utf8" else "frame.tiff"
    path = tmp_path / name
    path.write_bytes(data)
    file_reads = []
    real_imread = cv2.imread
    monkeypatch.setattr(image_files.cv2, "imread", lambda p, f: file_reads.append(p) or real_imread(p, f))
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is not None
    reason = image_files.decoded_from_memory_because(path)
    assert (reason is None) == bool(file_reads) and (reason is None) == (kind == "plain")
    # the choice changed in its one place: the read follows it, as the reason does
    monkeypatch.setattr(image_files, "_memory_decode_because", lambda p, resets: "told so")
    file_reads.clear()
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is not None and not file_reads
    assert image_files.decoded_from_memory_because(path) == "told so"


def test_a_webp_compressed_tiff_is_refused_or_read_as_the_build_s_probe_says(tmp_path, monkeypatch):
    """Compression 50001 (WebP), which OpenCV 5.0.0 leaves out and 5.1 includes, follows the installed build's
    probe (``tiff_compression.decoded``): refused, naming the codec, where the probe fails; handed to OpenCV where
    it decodes (faked here: a build without the codec then gives None, not a refusal)."""
    path = tmp_path / "view.tiff"
    path.write_bytes(tiff_compression.webp_sample())
    for decodes in (False, True):
        tiff_compression.decoded.cache_clear()
        monkeypatch.setattr(tiff_compression, "decodes_sample", lambda sample, decodes=decodes: decodes)
        refusal = image_files.tiff_compression_refusal(path)
        assert (refusal is None) == decodes
        assert decodes or "Compression 50001 (WebP)" in image_files.unread_because(path, cv2.IMREAD_COLOR)
    tiff_compression.decoded.cache_clear()


# ------------------------------------------------------------------ a TIFF's strips not holding its image (session 66)
@pytest.mark.parametrize("compression", [1, 5, 8, 32773])
def test_a_tiff_whose_strip_runs_past_its_end_is_refused_naming_the_strip(tmp_path, compression):
    """OpenCV gave None already (libtiff's read error), the cause unnamed: every caller called it unreadable."""
    path = tmp_path / "view.tiff"
    path.write_bytes(tiff_with_strip_count(compression, 1, lambda count, size, offset: size + 100 - offset))
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    assert image_files.unread_because(path, cv2.IMREAD_COLOR).startswith(
        f"its strip 2 runs past the file's end (to byte {path.stat().st_size + 100} of {path.stat().st_size})")


def test_an_uncompressed_strip_holding_fewer_bytes_than_its_rows_is_refused_not_read_part_black(tmp_path):
    """Strip 2 (22 rows of 64 RGB pixels: 4224 bytes) said to hold half of them: OpenCV 5.0 delivered the image with
    the rest black, libtiff only warning. Refused now, from the header, the strip named."""
    data = tiff_with_strip_count(1, 1, lambda count, size, offset: count // 2)
    with tiff_compression.opencv_log_silenced():
        part_black = cv2.imdecode(as_array(data), cv2.IMREAD_COLOR)
    assert part_black is not None and (part_black == 0).all(axis=2).any()  # what OpenCV 5.0 delivers
    path = tmp_path / "view.tiff"
    path.write_bytes(data)
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    assert decode_image_or_none(as_array(data), cv2.IMREAD_UNCHANGED) is None
    assert image_files.unread_because(path, cv2.IMREAD_COLOR) == (
        "its strip 2 holds 2112 of the 4224 bytes its pixels need (uncompressed): OpenCV would deliver the rest black")


def test_a_tiff_whose_strips_hold_their_data_is_read_and_one_strip_s_wrong_count_is_left_to_libtiff(tmp_path):
    """Not refused: strips holding more than their rows (OpenCV's compressed ones hold any size), and a single
    uncompressed strip whose byte count is wrong (too small or 0): libtiff then reads the rows the file holds."""
    image = STRIPS_IMAGE[:16, :16]
    whole = tiff_compression.single_strip_rgb_tiff(16, 16, 1, image[..., ::-1].tobytes())
    for data in (whole, whole.replace(struct.pack("<HHII", 279, 4, 1, 768), struct.pack("<HHII", 279, 4, 1, 100)),
                 whole.replace(struct.pack("<HHII", 279, 4, 1, 768), struct.pack("<HHII", 279, 4, 1, 0))):
        assert np.array_equal(decode_image_or_none(as_array(data), cv2.IMREAD_COLOR), image)
    more = tiff_with_strip_count(1, 0, lambda count, size, offset: count + 10)
    assert np.array_equal(decode_image_or_none(as_array(more), cv2.IMREAD_COLOR), STRIPS_IMAGE)


def test_garbage_in_a_tiff_s_compressed_data_gives_no_sign_opencv_reads_it_part_black(tmp_path):
    """The limit (session 66): LZW data overwritten with garbage decodes part black, cv2.imread and cv2.imdecode
    alike, libtiff's error only logged; its header is whole, so nothing here refuses it. Should an OpenCV release
    fail on it instead, this test says so."""
    data = bytearray(cv2.imencode(".tiff", STRIPS_IMAGE, [cv2.IMWRITE_TIFF_COMPRESSION, 5])[1].tobytes())
    tags = tiff_header.read_tags(io.BytesIO(bytes(data)), tiff_header.IMAGE_DATA_TAGS,
                                 unlimited=tiff_header.IMAGE_DATA_TAGS)
    start, count = tags.get(273).values[1], tags.get(279).values[1]
    data[start + count // 3:start + count] = np.random.default_rng(2).integers(0, 256, count - count // 3,
                                                                               np.uint8).tobytes()
    path = tmp_path / "view.tiff"
    path.write_bytes(bytes(data))
    assert image_files.tiff_data_refusal(path) is None
    with tiff_compression.opencv_log_silenced():
        for image in (cv2.imread(str(path), cv2.IMREAD_COLOR), read_image_or_none(path, cv2.IMREAD_COLOR)):
            assert image is not None and (image == 0).all(axis=2).any()


def test_an_uncompressed_tile_holding_fewer_bytes_than_a_tile_is_refused(tmp_path):
    """Tiles (16x16, RGB: 768 bytes each, those at the edges padded) as libtiff writes them: read; the last one said
    to hold a byte less: refused, naming it (libtiff reads a whole tile or fails on it)."""
    image = STRIPS_IMAGE[:20, :40]
    tiled = tiff_tiled(image, (16, 16))
    path = tmp_path / "view.tiff"
    path.write_bytes(tiled)
    assert np.array_equal(read_image_or_none(path, cv2.IMREAD_COLOR), image)
    counts = tiff_entries(tiled)[325][1]
    path.write_bytes(tiff_laid_out(tiled, changed={325: (4, counts[:-1] + (counts[-1] - 1,))}))
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    assert image_files.unread_because(path, cv2.IMREAD_COLOR).startswith(
        f"its tile {len(counts)} holds 767 of the 768 bytes its pixels need")


def test_each_cause_of_an_unread_image_says_what_it_makes_of_the_file(tmp_path):
    """unread_cause, the one chain of causes (replay's load_image types its error by the kind, where it repeated
    the chain with its own calls): a compression this OpenCV does not decode is a refused layout, a strip short of
    its bytes a damaged file, float samples read to 8 bits a read these flags cannot make; unread_because is its
    text, and a corrupt file has no cause."""
    jpeg2000, short_strip, floats, corrupt = (tmp_path / name for name in ("j2k.tiff", "strip.tiff", "float.tiff",
                                                                           "corrupt.png"))
    jpeg2000.write_bytes(tiff_of_compression(stored_image(3), 34712))
    short_strip.write_bytes(tiff_with_strip_count(1, 1, lambda count, size, offset: count - 1))
    assert cv2.imwrite(str(floats), np.full((6, 8), 0.5, np.float32))
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n cut")
    for path, kind, start in [(jpeg2000, image_files.UnreadKind.REFUSED_LAYOUT, "it is a TIFF of Compression 34712"),
                              (short_strip, image_files.UnreadKind.DAMAGED, "its strip 2 holds 4223 of the 4224"),
                              (floats, image_files.UnreadKind.NOT_WITH_THESE_FLAGS, "it has float32 samples")]:
        cause = image_files.unread_cause(path, cv2.IMREAD_COLOR)
        assert cause.kind is kind and cause.text.startswith(start), path
        assert image_files.unread_because(path, cv2.IMREAD_COLOR) == cause.text
    assert image_files.unread_cause(floats, cv2.IMREAD_UNCHANGED) is None
    assert image_files.unread_cause(corrupt, cv2.IMREAD_COLOR) is None


def _noise_jpeg() -> bytes:
    return cv2.imencode(".jpg", np.random.default_rng(1).integers(0, 256, (24, 32, 3), dtype=np.uint8))[1].tobytes()


@pytest.mark.parametrize("cut", [lambda d: d[:len(d) // 3], lambda d: d[:-2], lambda d: d[:len(d) // 3] + bytes(40)])
def test_a_jpeg_cut_short_does_not_read_and_says_so(tmp_path, cut):
    """OpenCV's file reader filled a JPEG cut short with grey (libjpeg's "Premature end" only logged); imdecode,
    replay's read, refuses it. Cut to a third, missing only its end-of-image marker, or cut and padded."""
    path = tmp_path / "cut.jpg"
    path.write_bytes(cut(_noise_jpeg()))
    assert read_image_or_none(path, cv2.IMREAD_COLOR) is None
    cause = image_files.unread_cause(path, cv2.IMREAD_COLOR)
    assert cause == image_files.UnreadCause(
        f"it is a JPEG cut short ({path.stat().st_size} bytes, not ending at its end-of-image marker FFD9)",
        image_files.UnreadKind.DAMAGED)


@pytest.mark.parametrize("tail", [b"", bytes(100), b"\xff" * 3, b"another tool's trailer"])
def test_a_whole_jpeg_reads_as_imdecode_reads_it_whatever_follows_its_end(tmp_path, tail):
    data = _noise_jpeg()
    path = tmp_path / "whole.jpg"
    path.write_bytes(data + tail)
    expected = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(read_image_or_none(path, cv2.IMREAD_COLOR), expected)
