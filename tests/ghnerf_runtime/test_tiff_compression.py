"""ghnerf_runtime.tiff_compression: which TIFF Compression values the installed OpenCV decodes, checked against it
(a later OpenCV that decodes another one, or stops decoding one, fails here first)."""
from __future__ import annotations

import contextlib
import struct
import zlib

import cv2
import numpy as np
import pytest

from ghnerf_runtime import tiff_compression
from tests.odd_images import tiff_entries

#: A small 8-bit BGR image: none of its samples zero, so an image of zeros is told from it.
IMAGE = np.random.default_rng(64).integers(1, 256, (16, 16, 3), np.uint8)


def uncompressed_tagged(compression: int) -> bytes:
    """:data:`IMAGE` as an uncompressed TIFF (as OpenCV writes one) whose Compression says ``compression``."""
    data = bytearray(cv2.imencode(".tiff", IMAGE, [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes())
    assert tiff_entries(bytes(data))[259] == (3, (1,))
    (ifd,) = struct.unpack_from("<I", data, 4)
    (count,) = struct.unpack_from("<H", data, ifd)
    entry = next(ifd + 2 + 12 * n for n in range(count) if struct.unpack_from("<H", data, ifd + 2 + 12 * n)[0] == 259)
    struct.pack_into("<H", data, entry + 8, compression)  # its value, held in the entry
    return bytes(data)


def test_each_compression_opencv_writes_is_one_it_decodes():
    """cv2.imwrite writes none, LZW, JPEG, both deflates and PackBits (and LZW where asked for DNG's lossy JPEG or
    JPEG XL); an OpenCV built with more codecs (LZMA, Zstandard, WebP, ...) writes those too: one probed (WebP) is
    then decoded() by the probe, another must join the probes."""
    written = set()
    with tiff_compression.opencv_log_silenced():
        for compression in sorted(tiff_compression.NAMES):
            with contextlib.suppress(cv2.error):
                ok, data = cv2.imencode(".tiff", IMAGE, [cv2.IMWRITE_TIFF_COMPRESSION, compression])
                if ok and tiff_entries(data.tobytes())[259][1] == (compression,) \
                        and cv2.imdecode(data, cv2.IMREAD_COLOR) is not None:
                    written.add(compression)
    assert written - set(tiff_compression.PROBED) == {1, 5, 7, 8, 32773, 32946}  # (5.1 writes WebP too)
    assert written <= tiff_compression.decoded()


def test_opencv_reads_a_tiff_of_a_compression_it_has_no_codec_for_as_an_image_of_zeros():
    """The reason for the refusal (docs/recording-format.md, "Images"): JPEG 2000 (34712) and any unregistered
    value decode to the stored size, every sample zero, libtiff's error only logged. Should an OpenCV release fail
    on them instead, this test says so."""
    with tiff_compression.opencv_log_silenced():
        for compression in (34712, 65000):
            data = np.frombuffer(uncompressed_tagged(compression), np.uint8)
            decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
            assert decoded.shape == IMAGE.shape and not decoded.any(), compression


def test_no_compression_outside_decoded_decodes_and_none_inside_it_is_read_as_zeros():
    """Every Compression value (65536), on a small uncompressed TIFF: one outside decoded() never gives the image
    (None, or zeros: refusing it loses nothing), and one inside it that cv2.imwrite does not write fails on 8-bit
    data (None: CCITT fax is 1-bit, ThunderScan 4-bit, NeXT 2-bit, SGILog LogLuv), never an image of zeros."""
    black, decoded_as_zeros = [], []
    with tiff_compression.opencv_log_silenced():
        for compression in range(1 << 16):
            image = cv2.imdecode(np.frombuffer(uncompressed_tagged(compression), np.uint8), cv2.IMREAD_COLOR)
            if compression not in tiff_compression.decoded():
                if image is not None and image.any():
                    black.append(compression)
            elif compression not in (1, 5, 7, 8, 32773, 32946) and image is not None:
                decoded_as_zeros.append(compression)
    assert black == [] and decoded_as_zeros == []


@pytest.mark.parametrize(("compression", "said"), [
    (34712, "a TIFF of Compression 34712 (JPEG 2000), which OpenCV"),
    (50000, "a TIFF of Compression 50000 (Zstandard), which OpenCV"),
    (65000, "a TIFF of Compression 65000 (unregistered), which OpenCV"),
])
def test_a_compression_not_decoded_is_refused_by_number_and_name(compression, said):
    assert tiff_compression.refusal(compression).startswith(said)
    assert f"OpenCV {cv2.__version__}'s libtiff does not decode" in tiff_compression.refusal(compression)


def test_a_compression_decoded_is_not_refused():
    assert all(tiff_compression.refusal(compression) is None for compression in tiff_compression.decoded())


# ------------------------------------------------------------------ optional codecs, probed (session 66)
@pytest.fixture
def fresh_probe():
    """:func:`tiff_compression.decoded` probed anew in the test (its cache cleared before and after it)."""
    tiff_compression.decoded.cache_clear()
    yield
    tiff_compression.decoded.cache_clear()


@pytest.mark.parametrize(("compression", "packed"), [
    (1, lambda strip: strip), (8, zlib.compress)], ids=["none", "deflate"])
def test_the_probe_s_tiff_layout_decodes_under_a_built_in_codec(compression, packed):
    """The WebP sample's layout (one 8-bit RGB strip, built byte by byte) with a codec every build has decodes to
    the probe's image: where a build fails the WebP sample, it is the codec it lacks, not the layout."""
    image = tiff_compression._probe_image()
    strip = packed(image[..., ::-1].tobytes())  # stored RGB
    assert tiff_compression.decodes_sample(tiff_compression.single_strip_rgb_tiff(8, 8, compression, strip))


def test_webp_is_decoded_exactly_where_the_installed_build_decodes_the_probe_s_sample(fresh_probe):
    """OpenCV 5.0.0 (the wheel installed in session 66) lacks libtiff's WebP codec: refused, its message saying so.
    A build including it (5.1) decodes the sample and accepts 50001; either way the probe and the build agree."""
    build_decodes = cv2.imdecode(np.frombuffer(tiff_compression.webp_sample(), np.uint8), cv2.IMREAD_COLOR) is not None
    assert (50001 in tiff_compression.decoded()) == build_decodes
    if not build_decodes:
        assert "built without that codec" in tiff_compression.refusal(50001)


def test_a_build_whose_probe_decodes_webp_accepts_it(fresh_probe, monkeypatch):
    """Faked where the installed build lacks the codec: a probe that decodes the sample makes 50001 decoded (not
    refused), and leaves the compressions no probe names refused."""
    monkeypatch.setattr(tiff_compression, "decodes_sample", lambda sample: bool(sample))
    assert 50001 in tiff_compression.decoded() and tiff_compression.refusal(50001) is None
    assert tiff_compression.refusal(34712) is not None and tiff_compression.refusal(50000) is not None


def test_a_build_whose_probe_fails_refuses_webp_naming_the_codec_it_lacks(fresh_probe, monkeypatch):
    monkeypatch.setattr(tiff_compression, "decodes_sample", lambda sample: False)
    assert tiff_compression.refusal(50001) == (
        f"a TIFF of Compression 50001 (WebP), which OpenCV {cv2.__version__}'s libtiff does not decode (its libtiff "
        f"was built without that codec, as a decode of a sample showed; an OpenCV build that includes it decodes "
        f"the file as it is): rewrite it uncompressed or with LZW, deflate or PackBits")


def test_the_probe_runs_once_a_process(fresh_probe, monkeypatch):
    probes = []
    monkeypatch.setattr(tiff_compression, "decodes_sample", lambda sample: probes.append(sample) or False)
    for _ in range(3):
        tiff_compression.refusal(50001)
    assert tiff_compression.refusal(1) is None and len(probes) == len(tiff_compression.PROBED)


def test_opencv_s_log_is_silent_inside_the_block_and_restored_after_even_on_an_error():
    before = cv2.utils.logging.getLogLevel()
    with pytest.raises(cv2.error), tiff_compression.opencv_log_silenced():
        assert cv2.utils.logging.getLogLevel() == cv2.utils.logging.LOG_LEVEL_SILENT
        raise cv2.error("a decode that fails")
    assert cv2.utils.logging.getLogLevel() == before
