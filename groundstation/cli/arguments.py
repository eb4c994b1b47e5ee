"""Number types for argparse options, with the rule each option's value must meet.

A bad value on the command line is answered by argparse with exit status 2 and a line
that names the option, the value given and what it must be ("--psd-segment: must be > 0,
not -3"), before anything is opened or started.
"""

from __future__ import annotations

import argparse
import math
from typing import Callable


def number(accept: Callable[[float], bool], must: str, *, convert: Callable = float,
           what: str = "a number") -> Callable[[str], float]:
    """An argparse `type`: `convert(text)`, refused unless `accept(value)`; `must` is
    the rule in words, `what` the kind of value expected."""
    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not {what}: {text!r}") from None
        if not accept(value):
            raise argparse.ArgumentTypeError(f"{must}, not {text}")
        return value
    parse.__name__ = what.split()[-1]           # argparse's fallback wording
    return parse


positive = number(lambda v: 0 < v < math.inf, "must be > 0")
non_negative = number(lambda v: 0 <= v < math.inf, "must be >= 0")
fraction = number(lambda v: 0 <= v <= 1, "must be a fraction from 0 to 1")
seconds = number(math.isfinite, "must be a finite number of seconds",
                 what="a number of seconds")
positive_seconds = number(lambda v: 0 < v < math.inf, "must be a finite number of seconds > 0",
                          what="a number of seconds")
count = number(lambda v: v >= 1, "must be >= 1", convert=int, what="a whole number")


#: where a listening port the user chooses binds when no host is given: this host only
LOOPBACK = "127.0.0.1"


def listen_address(text: str) -> tuple[str, int]:
    """An argparse `type` for a port to listen on: `PORT` (on 127.0.0.1) or `HOST:PORT`
    (`[IPv6]:PORT`); PORT 0 lets the system choose.  Returns (host, port)."""
    host, sep, port_text = text.rpartition(":")
    host = host.strip("[]") if sep else LOOPBACK
    try:
        port = int(port_text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be PORT or HOST:PORT (e.g. 8786 or 0.0.0.0:8786), not {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"the port must be 0 (any free port) .. 65535, not {port}")
    if sep and not host:
        raise argparse.ArgumentTypeError(f"no host before the ':' in {text!r}: give HOST:PORT, or "
                                         f"PORT alone for {LOOPBACK}")
    return host, port


listen_address.__name__ = "address"            # argparse's fallback wording


def command_group(sub: argparse._SubParsersAction, name: str, help_text: str,
                  *adders: Callable[[argparse._SubParsersAction], None]
                  ) -> argparse._SubParsersAction:
    """`groundstation NAME ACTION ...`: a command of several actions, each declared by
    one of `adders` on the group's subparsers (returned, for a module to add more)."""
    group = sub.add_parser(name, help=help_text)
    actions = group.add_subparsers(dest=f"{name}_action", required=True, metavar="ACTION")
    for add in adders:
        add(actions)
    return actions
