"""A figure beside the bound it broke, written so that it never reads as the bound itself."""
from __future__ import annotations

__all__ = ["past_bound"]

#: Most digits tried: a float64 reads back exactly from 17 significant digits.
_MOST_DIGITS = 17


def past_bound(value: float, bound: float, digits: int, style: str = "g") -> str:
    """``value`` as ``format(value, f".{digits}{style}")``, with as many more digits as it takes to differ from
    ``bound`` written the same way: a value just past a bound was shown on it ("10.0 mm apart (at least 10 mm
    needed)", "lies 10% of the width ... (within 10%)"), which read as a refusal of an allowed value.

    A value on the bound (one figure of a message that broke another: a principal point off by exactly the
    tolerance along one axis) is shown as the bound, with ``digits``.

    Example:
        >>> past_bound(9.99999, 10.0, 1, "f"), past_bound(3.21, 10.0, 1, "f"), past_bound(0.1013, 0.1, 0, "%")
        ('9.99999', '3.2', '10.1%')
        >>> past_bound(0.1, 0.1, 0, "%")
        '10%'
    """
    if value == bound:  # no digits tell them apart: the search below ran out and wrote repr(0.1), "0.1" for "10%"
        return format(value, f".{digits}{style}")
    for places in range(digits, _MOST_DIGITS + 1):
        text = format(value, f".{places}{style}")
        if text != format(bound, f".{places}{style}"):
            return text
    return repr(value)
