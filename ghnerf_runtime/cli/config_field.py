"""A benchmark option that sets one field of a runtime config (``--rest-every`` sets
``TrackingConfig.cold_tiles_rest_every``), checked at parsing by the config's own validation: a value the config
refuses was its ConfigError traceback once the model was loaded, in some scripts once the sequences were rendered.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from ghnerf_runtime.cli.counts import ascii_integer
from ghnerf_runtime.errors import ConfigError

__all__ = ["config_field"]


def config_field(config_class: type, field: str,
                 parse: Callable[[str], Any] = ascii_integer) -> Callable[[str], Any]:
    """An argparse ``type=`` for a value of ``config_class``'s ``field``: read with ``parse`` (a ValueError or
    argparse's error: not a number), then refused, with the config's message (which names the field and the
    range), when ``config_class(field=value)`` is."""
    def checked(text: str) -> Any:
        try:
            value = parse(text)
        except (ValueError, argparse.ArgumentTypeError):
            raise argparse.ArgumentTypeError(f"{config_class.__name__}.{field}: not a number, got {text!r}") from None
        try:
            config_class(**{field: value})
        except ConfigError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        return value

    return checked
