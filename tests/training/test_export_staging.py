"""Moving checked graphs from ``<folder>.staging`` into a model folder: a Ctrl-C during the move, or a crash in it,
never leaves some new graphs beside old ones (same contract, other weights: the runtime loads them as one model)."""
from __future__ import annotations

import os
import signal

import pytest

from training.export import staging as st

NAMES = ("encoder.onnx", "volume.onnx", "render_heat.onnx")


def _folders(tmp_path):
    folder = tmp_path / "ghnerf"
    folder.mkdir()
    for n in NAMES:
        (folder / n).write_bytes(b"old " + n.encode())
    staging = st.staging_dir(folder)
    for n in NAMES:
        (staging / n).write_bytes(b"new " + n.encode())
    return folder, staging


def _contents(folder):
    return {n: (folder / n).read_bytes().split()[0] for n in NAMES}


def test_a_ctrl_c_during_the_move_is_held_until_every_file_is_in(tmp_path, monkeypatch):
    """A Ctrl-C after the first graph moved used to stop the move there: encoder new, volume and render_heat old."""
    folder, staging = _folders(tmp_path)
    replace = os.replace

    def replace_then_ctrl_c(src, dst):
        replace(src, dst)
        if str(dst).endswith("encoder.onnx") and str(src).startswith(str(staging)):
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace_then_ctrl_c)
    with pytest.raises(KeyboardInterrupt):  # still stops the program, once the files are in
        st.move_into(staging, folder, [staging / n for n in NAMES])
    monkeypatch.undo()
    assert _contents(folder) == dict.fromkeys(NAMES, b"new")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler is put back


def test_a_move_cut_short_by_a_crash_is_finished_by_the_next_attempt(tmp_path, monkeypatch):
    """A process killed after the first graph moved left the folder mixed, and the next staging_dir removed the
    staged rest: the folder stayed mixed until a whole export passed again."""
    folder, staging = _folders(tmp_path)
    replace = os.replace

    class Killed(BaseException):
        pass

    def replace_then_die(src, dst):
        if str(dst).endswith("volume.onnx"):
            raise Killed  # what a kill -9 leaves: encoder moved, volume and render_heat still staged
        replace(src, dst)

    monkeypatch.setattr(os, "replace", replace_then_die)
    with pytest.raises(Killed):
        st.move_into(staging, folder, [staging / n for n in NAMES])
    monkeypatch.undo()
    assert _contents(folder)["encoder.onnx"] == b"new" and _contents(folder)["volume.onnx"] == b"old"
    again = st.staging_dir(folder)  # the next export (or make model) of the folder
    assert _contents(folder) == dict.fromkeys(NAMES, b"new")
    assert again == staging and list(again.iterdir()) == []


def test_a_whole_move_leaves_no_list_behind(tmp_path):
    folder, staging = _folders(tmp_path)
    assert st.move_into(staging, folder, [staging / n for n in NAMES]) == [folder / n for n in NAMES]
    assert _contents(folder) == dict.fromkeys(NAMES, b"new") and not staging.exists()
    assert st.finish_interrupted_move(staging, folder) == []


@pytest.mark.parametrize("files", [["ghnerf/encoder.onnx"], "ghnerf/encoder.onnx", 3])
def test_a_card_whose_files_are_no_object_is_left_as_unreadable_cards_are_and_the_move_goes_on(tmp_path, files):
    """A hand-edited card whose ``files`` is a list stopped the export after its parity checks, in an
    AttributeError traceback from the staleness check before the move."""
    import json

    folder, staging = _folders(tmp_path)
    card = tmp_path / "model_card.json"
    card.write_text(json.dumps({"files": files}))
    st.move_into(staging, folder, [staging / n for n in NAMES])
    assert _contents(folder) == dict.fromkeys(NAMES, b"new") and not staging.exists()
    assert json.loads(card.read_text()) == {"files": files} and not (tmp_path / st.STALE_CARD).exists()
