"""ghnerf_runtime.json_keys: the one JSON parse the rig file, the configs and a take's files share."""
from __future__ import annotations

import pytest

from ghnerf_runtime.json_keys import MAX_JSON_DEPTH, JsonTextError, first_repeat, loads_remembering


@pytest.mark.parametrize("text, said, placed", [
    ('{"a": 1,\n "b": }', "invalid JSON at line 2, column 7: Expecting value", True),
    ("[" * 100_000 + "]" * 100_000, "invalid JSON: nested too deeply", False),  # a RecursionError
    # parsed, then a RecursionError from the readers' recursive walks (first_repeat, the plain copies)
    ('{"a": ' + "[" * 900 + "]" * 900 + "}", "invalid JSON: nested too deeply (objects and arrays more than", False),
    ("1" * 5000, "invalid JSON: Exceeds the limit (4300 digits)", False),  # Python's integer limit
])
def test_every_unreadable_text_is_one_error(text, said, placed):
    with pytest.raises(JsonTextError) as e:
        loads_remembering(text)
    assert str(e.value).startswith(said) and (e.value.line is not None) == placed


def test_nesting_is_taken_up_to_max_json_depth():
    at_the_bound = "[" * (MAX_JSON_DEPTH - 1) + "{}" + "]" * (MAX_JSON_DEPTH - 1)
    assert first_repeat(loads_remembering(at_the_bound)) is None
    with pytest.raises(JsonTextError, match="more than 128 levels"):
        loads_remembering("[" + at_the_bound + "]")


def test_repeated_keys_are_remembered_at_any_depth():
    value = loads_remembering('{"rig": {"cameras": [{"K": 1, "K": 2}]}}')
    assert value["rig"]["cameras"][0]["K"] == 2 and first_repeat(value) == "rig.cameras[0].K"
    assert first_repeat(loads_remembering('{"a": [1, {"b": 2}]}')) is None


class _Refused(ValueError):
    """What a reader's own hook raises (calibration.board refuses a repeated key, naming both values)."""


def _refusing_hook(pairs):
    if len({key for key, _ in pairs}) < len(pairs):
        raise _Refused("a key given twice")
    return dict(pairs)


def test_a_hook_in_place_of_the_remembering_one_keeps_the_checks_and_its_own_errors():
    """The board file and ``cameras.json`` parse through :func:`loads_remembering` too (session 68), the board with
    its own hook: the depth bound holds for it (they read 129-990 levels as a field error), and what the hook raises
    comes out as it is, not as the parser's "invalid JSON" (both are ValueErrors)."""
    assert loads_remembering('{"a": [1, 2]}', object_pairs_hook=_refusing_hook) == {"a": [1, 2]}
    with pytest.raises(_Refused, match="given twice"):
        loads_remembering('{"a": 1, "a": 2}', object_pairs_hook=_refusing_hook)
    with pytest.raises(JsonTextError, match="more than 128 levels"):
        loads_remembering('{"a": ' + "[" * 200 + "]" * 200 + "}", object_pairs_hook=_refusing_hook)
    with pytest.raises(JsonTextError, match="Exceeds the limit"):
        loads_remembering('{"a": 1' + "0" * 5000 + "}", object_pairs_hook=_refusing_hook)
