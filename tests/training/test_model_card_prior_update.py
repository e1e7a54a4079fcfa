"""``python -m training.model_card --prior-metrics``: a new skeleton prior's eval rescores only the prior's columns."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from training import model_card

MODELS = Path(__file__).resolve().parents[2] / "models"
CARD_FILES = ("model_card.json", "metrics.json", "metrics_ghnerf.json", "metrics_baseline.json", "MODEL_CARD.md")


@pytest.fixture
def card_dir(tmp_path):
    for name in CARD_FILES:
        shutil.copy(MODELS / name, tmp_path / name)
    return tmp_path


def _report(tmp_path, card_dir, **override):
    card = json.loads((card_dir / "model_card.json").read_text())
    models = {label: {**card["metrics"][label], "skeleton_prior_mpjpe_mm": 12.345, "mpjpe_mm": -1.0}
              for label in ("ghnerf_fp32", "ghnerf_int8")}
    report = {"data": card["data"]["path"], "split": card["data"]["eval_split"], "models": models, **override}
    path = tmp_path / "eval.json"
    path.write_text(json.dumps(report))
    return path


def test_only_the_prior_columns_change(tmp_path, card_dir):
    before = {name: (card_dir / name).read_text() for name in CARD_FILES}
    assert model_card.main(["--card-dir", str(card_dir), "--prior-metrics", str(_report(tmp_path, card_dir))]) == 0
    card = json.loads((card_dir / "model_card.json").read_text())
    old = json.loads(before["model_card.json"])
    for label in ("ghnerf_fp32", "ghnerf_int8"):
        assert card["metrics"][label]["skeleton_prior_mpjpe_mm"] == 12.345
        assert card["metrics"][label]["mpjpe_mm"] == old["metrics"][label]["mpjpe_mm"]  # not a prior key: kept
    assert card["metrics"]["baseline_int8"] == old["metrics"]["baseline_int8"]
    assert (card_dir / "metrics_baseline.json").read_text() == before["metrics_baseline.json"]
    ghnerf = json.loads((card_dir / "metrics_ghnerf.json").read_text())
    assert ghnerf["models"]["ghnerf_int8"]["skeleton_prior_mpjpe_mm"] == 12.345
    after = (card_dir / "MODEL_CARD.md").read_text().splitlines()
    changed = [b for a, b in zip(before["MODEL_CARD.md"].splitlines(), after) if a != b]
    assert len(changed) == 2 and all(line.startswith(("| ghnerf_fp32 |", "| ghnerf_int8 |")) for line in changed), changed
    assert sum("| 12.3 /" in line for line in (card_dir / "MODEL_CARD.md").read_text().splitlines()) == 2


@pytest.mark.parametrize("override, words", [({"split": "val_seen_motions"}, "the card in"),
                                             ({"data": "data/other"}, "rerun ghnerf-eval"),
                                             ({"models": {"mystery": {}}}, "mystery")])
def test_a_report_of_another_dataset_or_model_is_refused_and_nothing_is_written(tmp_path, card_dir, capsys,
                                                                                 override, words):
    before = {name: (card_dir / name).read_bytes() for name in CARD_FILES}
    assert model_card.main(["--card-dir", str(card_dir), "--prior-metrics",
                            str(_report(tmp_path, card_dir, **override))]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m training.model_card: error: ") and words in err, err
    assert {name: (card_dir / name).read_bytes() for name in CARD_FILES} == before


@pytest.mark.parametrize("report, words", [([], "holds a JSON list, not a ghnerf-eval --out report object"),
                                           ({"models": ["ghnerf_fp32"]}, "'models' is a JSON list, not an object"),
                                           ({"models": {"ghnerf_fp32": 1}}, "models['ghnerf_fp32'] is a JSON int")])
def test_a_report_that_is_no_eval_report_object_is_named_not_a_traceback(tmp_path, card_dir, capsys, report, words):
    """A report that is a JSON list (or whose models are) ended in an AttributeError traceback."""
    before = {name: (card_dir / name).read_bytes() for name in CARD_FILES}
    path = tmp_path / "eval.json"
    path.write_text(json.dumps(report))
    assert model_card.main(["--card-dir", str(card_dir), "--prior-metrics", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"python -m training.model_card: error: {path}: ") and words in err, err
    assert {name: (card_dir / name).read_bytes() for name in CARD_FILES} == before


def test_a_card_that_is_no_card_object_is_named_not_a_traceback(tmp_path, card_dir, capsys):
    """A model_card.json that is a JSON list ended in a TypeError traceback."""
    report = _report(tmp_path, card_dir)
    (card_dir / "model_card.json").write_text("[]")
    assert model_card.main(["--card-dir", str(card_dir), "--prior-metrics", str(report)]) == 2
    err = capsys.readouterr().err
    assert f"error: {card_dir / 'model_card.json'} holds a JSON list, not a model card object" in err, err
    assert (card_dir / "model_card.json").read_text() == "[]"
