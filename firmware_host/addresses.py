"""Which of a host name's addresses to use: one rule for the udp:// sender and ``ghnerf-listen``.

A name with an IPv4 address is used over IPv4 (a receiver bound to 0.0.0.0 never hears ::1, which glibc
may list first for ``localhost``); a name with only IPv6 addresses, or an IPv6 literal, over IPv6.
Kept apart from ``sinks`` and ``listen`` so neither depends on the other.
"""
from __future__ import annotations

import socket
from collections.abc import Sequence
from typing import Any

AddrInfo = tuple[Any, Any, Any, Any, Any]  # as socket.getaddrinfo lists them


def ipv4_first(infos: Sequence[AddrInfo], keep: Any = None) -> tuple[int, Any]:
    """``(family, sockaddr)`` of the first IPv4 entry of a ``getaddrinfo`` answer, else of its first entry.

    ``keep``: the sockaddr in use, kept while the answer still lists it in the chosen family. A name with
    several addresses (round-robin DNS, a robot on Wi-Fi and Ethernet) comes back in another order from
    one lookup to the next; taking the first each time moved the stream between them.

    :raises ValueError: ``infos`` is empty.
    """
    if not infos:
        raise ValueError("no address")
    family, _, _, _, addr = min(infos, key=lambda info: info[0] != socket.AF_INET)  # stable: keeps the order
    if keep is not None and any(info[0] == family and info[4] == keep for info in infos):
        return family, keep
    return family, addr
