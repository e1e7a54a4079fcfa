"""``ghnerf_runtime.image_write``: an image file written whole or not at all, a FIFO or device written into."""
import os
import threading

import cv2
import numpy as np
import pytest

from ghnerf_runtime.errors import ImageWriteError
from ghnerf_runtime.image_write import write_image_atomic


def _image() -> np.ndarray:
    return np.arange(24 * 32 * 3, dtype=np.uint8).reshape(24, 32, 3)


def _png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    assert ok
    return data.tobytes()


def test_a_fifo_is_written_into_and_its_reader_gets_the_whole_image(tmp_path):
    """A file renamed over a FIFO left the viewer reading it waiting forever, the FIFO gone from the folder."""
    fifo = tmp_path / "view.png"
    os.mkfifo(fifo)
    os.link(fifo, tmp_path / "same-fifo")  # reaches the FIFO to end its reader's wait should it be renamed over
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    try:
        write_image_atomic(fifo, _image())
        reader.join(timeout=10)
    finally:
        if reader.is_alive():  # the write never opened the FIFO: a writer opened and closed gives its reader EOF
            os.close(os.open(tmp_path / "same-fifo", os.O_WRONLY | os.O_NONBLOCK))
            reader.join(timeout=10)
    assert fifo.is_fifo()
    assert got == [_png(_image())]


def test_a_regular_file_is_replaced_by_a_new_file_the_earlier_one_never_truncated(tmp_path):
    path = tmp_path / "out.png"
    path.write_bytes(b"earlier")
    with open(path, "rb") as earlier:  # the earlier file as a reader holding it open sees it
        before = os.fstat(earlier.fileno()).st_ino
        write_image_atomic(path, _image())
        assert earlier.read() == b"earlier"
    assert os.stat(path).st_ino != before
    assert path.read_bytes() == _png(_image())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]  # no temporary file left beside it


def test_an_unknown_suffix_raises_naming_the_path_and_leaves_the_earlier_file(tmp_path):
    path = tmp_path / "out.xyz"
    path.write_bytes(b"earlier")
    with pytest.raises(ImageWriteError) as info:
        write_image_atomic(path, _image())
    assert info.value.path == str(path) and str(info.value).startswith(f"{path}: cannot encode the image")
    assert path.read_bytes() == b"earlier"
