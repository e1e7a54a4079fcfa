"""The runtime config tree: validated once, unknown keys rejected by their dotted path."""
from __future__ import annotations

import json
from dataclasses import replace

import pytest

from ghnerf_runtime.config import (
    EstimatorConfig,
    HeatmapsConfig,
    Joints3DConfig,
    NovelViewConfig,
    RoiConfig,
    SessionConfig,
    config_from_dict,
    config_to_dict,
    load_config,
)
from ghnerf_runtime.errors import ConfigError


def test_defaults_round_trip():
    cfg = EstimatorConfig()
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert config_from_dict({}) == cfg
    json.dumps(config_to_dict(cfg))  # JSON-ready


@pytest.mark.parametrize("data, key", [
    ({"sesion": {}}, "sesion"),
    ({"joints3d": {"metod": "volumetric"}}, "joints3d.metod"),
    ({"novel_view": {"enabled": True, "strides": 2}}, "novel_view.strides"),
])
def test_unknown_keys_are_named(data, key):
    with pytest.raises(ConfigError) as e:
        config_from_dict(data)
    assert e.value.key == key and str(e.value).startswith(key) and "unknown key" in str(e.value)


@pytest.mark.parametrize("data, key", [
    ({"joints3d": {"method": "magic"}}, "joints3d.method"),
    ({"session": {"threads": 0}}, "session.threads"),
    ({"session": {"precision": "int4"}}, "session.precision"),
    ({"session": {"precision_overrides": {"encoder": "int4"}}}, "session.precision_overrides"),
    ({"novel_view": {"stride": 3}}, "novel_view.stride"),
    ({"novel_view": {"enabled": "yes"}}, "novel_view.enabled"),
    ({"tracking": {"min_joints": 1}}, "tracking.min_joints"),
    ({"frame_check": {"min_std": float("nan")}}, "frame_check.min_std"),
    ({"decoder": {"threshold": 2.0}}, "decoder.threshold"),  # was "decoder" alone
    ({"decoder": {"sigma": 10**400}}, "decoder.sigma"),  # np.isfinite raised a bare TypeError
    ({"decoder": {"max_region_frac": float("inf")}}, "decoder.max_region_frac"),
    ({"roi": []}, "roi"),
    ({"roi": {"pad_fill": "mirror"}}, "roi.pad_fill"),
    ({"roi": {"pad_fade": 1.5}}, "roi.pad_fade"),
])
def test_bad_values_are_named(data, key):
    with pytest.raises(ConfigError) as e:
        config_from_dict(data)
    assert e.value.key == key, str(e.value)


def test_roi_pad_fill_follows_the_model_unless_set_and_a_bad_fill_or_reach_is_named_with_its_value():
    """An unset ``roi.pad_fill`` is the model's: "black" for a model trained on black frame padding (its
    contract's ``frame_padding``: what it learnt), "fade" (the repeated frame edge fading into the crop's mean over
    ``pad_fade`` crop sides) for one trained without, as the shipped model and older exports read; a fill set in
    the config wins over either (docs/runtime.md, "A person at the frame's edge")."""
    assert (RoiConfig().pad_fill, RoiConfig().pad_fade) == (None, 0.1)
    assert config_from_dict({"roi": {"pad_fill": None}}).roi.pad_fill is None  # null in a file: the model's
    assert RoiConfig().fill_for("black").pad_fill == "black" and RoiConfig().fill_for("none").pad_fill == "fade"
    for fill in ("black", "edge", "fade"):
        for padding in ("none", "black"):
            assert RoiConfig(pad_fill=fill).fill_for(padding).pad_fill == fill
    resolved = EstimatorConfig().beside_model("black")
    assert resolved.roi.pad_fill == "black" and resolved.roi.pad_fade == 0.1  # the rest of the tree as it was
    assert config_to_dict(resolved)["roi"]["pad_fill"] == "black"  # the effective config shows it
    assert RoiConfig(pad_fill="black").pad_fill == "black" and RoiConfig(pad_fade=0.0).pad_fade == 0.0
    for kwargs, key, shown in (({"pad_fill": "mirror"}, "RoiConfig.pad_fill", "'mirror'"),
                               ({"pad_fill": ""}, "RoiConfig.pad_fill", "''"),
                               ({"pad_fade": -0.1}, "RoiConfig.pad_fade", "-0.1"),
                               ({"pad_fade": "0.1"}, "RoiConfig.pad_fade", "'0.1'")):
        with pytest.raises(ConfigError) as e:
            RoiConfig(**kwargs)
        assert e.value.key == key and shown in str(e.value), str(e.value)
    with pytest.raises(ConfigError, match="fade"):  # the message lists the fills it takes
        RoiConfig(pad_fill="mean")


def test_required_graphs_follow_the_config():
    assert EstimatorConfig().required_graphs() == ("encoder",)  # encoder heatmaps + triangulation
    rendered = EstimatorConfig(heatmaps=HeatmapsConfig("rendered"))
    assert rendered.required_graphs() == ("encoder", "volume", "render_heat")
    cfg = EstimatorConfig(joints3d=Joints3DConfig(method="volumetric"), novel_view=NovelViewConfig(enabled=True))
    assert cfg.required_graphs() == ("encoder", "volume", "query", "render_rgb")
    cfg = replace(cfg, heatmaps=HeatmapsConfig("rendered"))
    assert cfg.required_graphs() == ("encoder", "volume", "render_heat", "query", "render_rgb")
    depth = EstimatorConfig(joints3d=Joints3DConfig(method="depth_centroid"))  # reads the rendered depth
    assert depth.required_graphs() == ("encoder", "volume", "render_heat")
    cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, heatmaps=True))
    assert "render" in cfg.required_graphs() and "render_rgb" not in cfg.required_graphs()


def test_load_config_names_the_file(tmp_path):
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"session": {"model_dir": "/opt/models", "precision": "fp32"}}))
    assert load_config(good).session == SessionConfig(model_dir="/opt/models", precision="fp32")
    bad = tmp_path / "bad.json"
    bad.write_text('{"session": {"model_dir": }')
    with pytest.raises(ConfigError, match="bad.json.*not valid JSON"):
        load_config(bad)
    typo = tmp_path / "typo.json"
    typo.write_text('{"rays": {"restrict": false}}')
    with pytest.raises(ConfigError, match="typo.json.*rays.restrict: unknown key"):
        load_config(typo)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "absent.json")


@pytest.mark.parametrize("text, key", [
    ('{"joints3d": {"method": "volumetric"}, "joints3d": {"grid": 8}}', "joints3d"),  # lost method, silently
    ('{"joints3d": {"method": "volumetric", "method": "triangulate"}}', "joints3d.method"),
])
def test_a_key_given_twice_is_named_not_dropped(tmp_path, text, key):
    path = tmp_path / "dup.json"
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(path)
    assert f"duplicate key {key!r}" in str(e.value) and str(e.value).startswith(str(path))


def test_a_config_file_with_a_byte_order_mark_loads(tmp_path):
    path = tmp_path / "bom.json"  # Windows editors write one; it was refused as invalid JSON
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps({"session": {"threads": 1}}).encode())
    assert load_config(path).session.threads == 1


@pytest.mark.parametrize("text, why", [
    ('{"session": {"threads": ' + "1" * 5000 + "}}", "4300 digits"),  # was a bare ValueError
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),  # was a RecursionError
    ('{"smoothing": {"enabled": ' + "[" * 500 + "]" * 500 + "}}", "nested too deeply"),  # parsed: a RecursionError
])
def test_json_python_cannot_hold_is_a_config_error(tmp_path, text, why):
    path = tmp_path / "odd.json"
    path.write_text(text)
    with pytest.raises(ConfigError, match=why) as e:
        load_config(path)
    assert e.value.key == str(path) and "not valid JSON" in str(e.value)


def test_a_config_path_with_a_nul_character_is_a_config_error():
    with pytest.raises(ConfigError, match="cannot read config file.*null byte"):  # was a bare ValueError
        load_config("runtime\0.json")


@pytest.mark.parametrize("given", ['{"roi": {"turn_search": false}}', ' [1]'])
def test_json_given_where_a_config_file_s_path_goes_is_said_so(given):
    # README: "--config with {...}" was read as the JSON itself, and the error said only "No such file or directory"
    with pytest.raises(ConfigError, match="a file's path is expected, not the JSON itself: write it into a file") as e:
        load_config(given)
    assert "cannot read config file (No such file or directory)" in str(e.value)


def test_a_missing_config_file_s_error_says_nothing_of_json(tmp_path):
    with pytest.raises(ConfigError, match=r"cannot read config file \(No such file or directory\)$"):
        load_config(tmp_path / "runtime.json")

def test_a_relative_model_dir_in_a_config_file_is_read_from_its_folder(tmp_path, monkeypatch):
    # read from the current directory, ghnerf-run --config / ghnerf-demo --config found it only from one folder
    (tmp_path / "conf").mkdir()
    path = tmp_path / "conf" / "runtime.json"
    path.write_text(json.dumps({"session": {"model_dir": "models"}}))
    monkeypatch.chdir(tmp_path)
    assert load_config(path).session.model_dir == str(tmp_path / "conf" / "models")
    path.write_text(json.dumps({"session": {"threads": 1}}))
    assert load_config(path).session.model_dir == "models"  # left out: the default, as before


@pytest.mark.parametrize("data", [[], None, "session", 3])
def test_a_root_that_is_not_an_object_is_named_as_the_root(data):
    """Keyed "EstimatorConfig" (a class, not a key the user wrote), the daemon named it
    ``estimator.EstimatorConfig: must be a mapping``; the root has no key."""
    with pytest.raises(ConfigError) as e:
        config_from_dict(data)
    assert e.value.key is None and str(e.value).startswith("must be a mapping (JSON object)"), str(e.value)


@pytest.mark.parametrize("content", [b"", b" \r\n\t\n", b"\xef\xbb\xbf"])
def test_an_empty_config_file_is_called_empty(tmp_path, content):
    """An empty file (a failed ``> config.json`` redirect) was "not valid JSON (line 1, column 1: Expecting
    value)"; it says so now, as the rig file does."""
    path = tmp_path / "empty.json"
    path.write_bytes(content)
    with pytest.raises(ConfigError) as e:
        load_config(path)
    assert str(e.value) == f"{path}: config file is empty"
