"""``python -m training.export --int8 --calib-npz``: calibration frames that are not what the runtime feeds the
model (0..255 pixels, channels last, another resolution) are refused before anything is exported."""
from __future__ import annotations

import re

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from ghnerf_runtime.contract import ModelContract  # noqa: E402
from training.configs import preset  # noqa: E402
from training.export.calibration import CalibrationDataError, load_calibration_npz  # noqa: E402
from training.export.cli import main  # noqa: E402
from training.model import GHNeRF  # noqa: E402


@pytest.fixture(scope="module")
def contract() -> ModelContract:
    return GHNeRF(preset("tiny")).contract()  # 64x64, two sources


def _npz(path, **arrays):
    np.savez(path, **arrays)
    return path


GOOD = np.random.default_rng(0).random((4, 2, 3, 64, 64)).astype(np.float32)  # MIN_FRAMES pairs


@pytest.mark.parametrize("arrays, what", [
    ({"images": (GOOD * 255).astype(np.uint8)}, r"'images' is uint8; the model wants float pixels in \[0, 1\]"),
    ({"images": GOOD * 255}, r"'images' values span \[0\.\d+, 254\.\d+\]; the model wants \[0, 1\]"),
    ({"images": GOOD.transpose(0, 1, 3, 4, 2)}, r"'images' has shape \[4, 2, 64, 64, 3\]; the model wants "
                                                r"\(F, 2, 3, 64, 64\)"),
    ({"images": np.zeros((2, 2, 3, 128, 128), np.float32)}, r"'images' has shape \[2, 2, 3, 128, 128\].* at the contract resolution 64x64"),
    ({"images": np.zeros((0, 2, 3, 64, 64), np.float32)}, r"'images' has shape \[0, 2, 3, 64, 64\]"),
    ({"images": np.where(GOOD > 0.5, np.nan, GOOD)}, r"'images' holds NaN or infinite values"),
    ({"frames": GOOD}, r"no 'images' array \(it holds \['frames'\]\)"),
    # too few pairs: MinMax ranges of one scene (one frame was accepted)
    ({"images": GOOD[:1]}, r"'images' holds 1 frame pair\(s\); int8 calibration wants at least 4"),
    ({"images": GOOD[:3]}, r"'images' holds 3 frame pair\(s\); int8 calibration wants at least 4"),
    # all black (a lens cap, a zero-filled buffer): accepted before, every range then fixed at one value
    ({"images": np.zeros_like(GOOD)}, r"'images' frame 0 source 0 is uniform \(every pixel 0; 8 of the 8 views "
                                      r"are\): a blank capture, not a scene"),
    # one blank view among real ones (a camera that had not started) is named
    ({"images": np.concatenate([GOOD[:2], np.ones_like(GOOD[:1]) * [[[[[1.0]]], [[[0.5]]]]], GOOD[3:]])},
     r"'images' frame 2 source 0 is uniform \(every pixel 1; 2 of the 8 views are\)"),
])
def test_frames_unlike_the_runtime_input_are_refused_naming_the_file(tmp_path, contract, arrays, what):
    path = _npz(tmp_path / "calib.npz", **arrays)
    with pytest.raises(CalibrationDataError, match=rf"^{re.escape(str(path))}: {what}"):
        load_calibration_npz(path, contract)


def _damaged_npz(path, damage: str):
    """An npz whose ``images.npy`` is damaged: its deflate stream (``zlib``), or its header cut inside the shape
    (``header``), as a disk or a cut copy leaves one."""
    import zipfile

    if damage == "zlib":  # 0xff opens a deflate block of the reserved type: zlib.error on the first read
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("images.npy", bytes(4096))
            info = zf.getinfo("images.npy")
        raw = bytearray(path.read_bytes())
        start = 30 + len(info.filename)  # the local header, no extra field
        raw[start:start + info.compress_size] = b"\xff" * info.compress_size
        path.write_bytes(bytes(raw))
    else:  # numpy reads a version 1.0 header through tokenize: an open bracket was its TokenError
        header = b"{'descr': '<f4', 'fortran_order': False, 'shape': (4, 2, "
        header += b" " * (63 - (10 + len(header)) % 64) + b"\n"
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("images.npy", b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header)
    return path


@pytest.mark.parametrize("damage", ["zlib", "header"])
def test_a_damaged_file_is_named_not_a_traceback(tmp_path, contract, damage):
    """zlib's and tokenize's errors from a damaged npz were tracebacks of the export."""
    path = _damaged_npz(tmp_path / "calib.npz", damage)
    with pytest.raises(CalibrationDataError, match=rf"^{re.escape(str(path))}: cannot read it as an npz file"):
        load_calibration_npz(path, contract)


@pytest.mark.parametrize("content", [b"not a zip", b""])  # b"": numpy's EOFError was a traceback of the export
def test_an_unreadable_file_is_named(tmp_path, contract, content):
    path = tmp_path / "calib.npz"
    path.write_bytes(content)
    with pytest.raises(CalibrationDataError, match=rf"^{re.escape(str(path))}: cannot read it as an npz file"):
        load_calibration_npz(path, contract)


def test_runtime_like_frames_load(tmp_path, contract):
    frames = load_calibration_npz(_npz(tmp_path / "calib.npz", images=GOOD.astype(np.float64)), contract)
    assert len(frames) == 4 and all(f.dtype == np.float32 and f.shape == (2, 3, 64, 64) for f in frames)
    np.testing.assert_array_equal(frames[1], GOOD[1])


def test_the_cli_refuses_uint8_frames_before_exporting(tmp_path, capsys):
    """0..255 frames calibrated every range 255x too wide and the export went on (exit 0); now exit 2, nothing
    written."""
    path = _npz(tmp_path / "calib.npz", images=(GOOD * 255).astype(np.uint8))
    out = tmp_path / "model"
    assert main(["--preset", "tiny", "--out", str(out), "--graphs", "human", "--int8", "--calib-npz",
                 str(path)]) == 2
    assert f"--calib-npz {path}: 'images' is uint8" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "model.staging").exists()


def test_the_cli_calibrates_on_checked_frames(tmp_path):
    out = tmp_path / "model"
    assert main(["--preset", "tiny", "--out", str(out), "--graphs", "human", "--int8", "--calib-npz",
                 str(_npz(tmp_path / "calib.npz", images=GOOD))]) == 0
    assert (out / "human.onnx").is_file() and (out / "human.int8.onnx").is_file()


def test_the_cli_refuses_calibration_frames_without_int8(tmp_path, capsys):
    """--calib-npz without --int8 was silently ignored: an fp32-only export the user thought calibrated."""
    out = tmp_path / "model"
    with pytest.raises(SystemExit) as e:
        main(["--preset", "tiny", "--out", str(out), "--graphs", "human", "--calib-npz",
              str(_npz(tmp_path / "calib.npz", images=GOOD))])
    assert e.value.code == 2
    assert "--calib-npz calibrates the int8 graphs: give --int8" in capsys.readouterr().err
    assert not out.exists()
