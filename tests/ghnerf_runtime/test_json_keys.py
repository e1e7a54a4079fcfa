"""ghnerf_runtime.json_keys: the one JSON parse the rig file, the configs and a take's files share."""
from __future__ import annotations

import pytest

from ghnerf_runtime.json_keys import JsonTextError, first_repeat, loads_remembering


@pytest.mark.parametrize("text, said, placed", [
    ('{"a": 1,\n "b": }', "invalid JSON at line 2, column 7: Expecting value", True),
    ("[" * 100_000 + "]" * 100_000, "invalid JSON: nested too deeply", False),  # a RecursionError
    ("1" * 5000, "invalid JSON: Exceeds the limit (4300 digits)", False),  # Python's integer limit
])
def test_every_unreadable_text_is_one_error(text, said, placed):
    with pytest.raises(JsonTextError) as e:
        loads_remembering(text)
    assert str(e.value).startswith(said) and (e.value.line is not None) == placed


def test_repeated_keys_are_remembered_at_any_depth():
    value = loads_remembering('{"rig": {"cameras": [{"K": 1, "K": 2}]}}')
    assert value["rig"]["cameras"][0]["K"] == 2 and first_repeat(value) == "rig.cameras[0].K"
    assert first_repeat(loads_remembering('{"a": [1, {"b": 2}]}')) is None
