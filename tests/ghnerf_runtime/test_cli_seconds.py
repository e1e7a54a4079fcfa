"""The one ``--seconds`` type of ghnerf-demo and ghnerf-listen (ghnerf_runtime.cli.seconds)."""
import argparse

import pytest

from firmware_host import demo, listen
from ghnerf_runtime.cli.seconds import positive_seconds


def test_a_finite_number_above_zero_is_taken():
    assert positive_seconds("1.5") == 1.5 and positive_seconds("30") == 30.0


# float() took the last three (other scripts' digits, '1_0') as 3, 3 and 10 seconds
@pytest.mark.parametrize("text", ["-1", "0", "nan", "inf", "soon", "", "\u0663", "\uff13", "1_0"])
def test_anything_else_is_refused_with_the_value_named(text):
    with pytest.raises(argparse.ArgumentTypeError, match=f"must be a finite number of seconds > 0, got {text!r}"):
        positive_seconds(text)


@pytest.mark.parametrize("text", ["-1", "soon"])
def test_demo_and_listen_refuse_a_value_in_the_same_words(text, capsys):
    # each had its own copy: "must be a number of seconds, got 'soon'" beside "..., not 'soon'"
    said = []
    for run in (lambda: demo.main(["--truth-only", f"--seconds={text}"]),
                lambda: listen.main(["udp://127.0.0.1:9", f"--seconds={text}"])):
        with pytest.raises(SystemExit):
            run()
        said.append(capsys.readouterr().err.strip().splitlines()[-1].partition("error: ")[2])
    assert said[0] == said[1] == f"argument --seconds: must be a finite number of seconds > 0, got {text!r}"
