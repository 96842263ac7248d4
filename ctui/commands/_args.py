"""argparse types for numeric options: finite, in range, bounded work.

``p.add_argument("--iso", type=number("--iso"))`` refuses ``nan``, ``inf``, ``1e308`` (or
whatever lies outside ``lo..hi``) at the parser, with argparse's usage line and exit 2,
before any file is read. The engine checks the same values again (its functions are
called by the TUI and by tests too).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

# largest coordinate / HU / mm value an option may give: far beyond any scanner's field
# of view or value range, small enough that products and squares stay finite
HUGE = 1e9


def command(subparsers: argparse._SubParsersAction, name: str, run: Callable[[argparse.Namespace], int], *,
            help: str, description: str, epilog: str | None = None,
            raw: bool = False) -> argparse.ArgumentParser:
    """The parser of ``ctui NAME``: its one-line ``help`` (in ``ctui --help``), its
    ``description`` and examples (``epilog``), and ``run`` as the function it calls.
    ``raw``: the description and examples keep their line breaks (examples on several
    lines); else argparse rewraps them."""
    formatter = argparse.RawDescriptionHelpFormatter if raw else argparse.HelpFormatter
    p = subparsers.add_parser(name, help=help, description=description, epilog=epilog, formatter_class=formatter)
    p.set_defaults(func=run)
    return p


def number(name: str, lo: float = -HUGE, hi: float = HUGE, *, integer: bool = False,
           above: bool = False) -> Callable[[str], float | int]:
    """An argparse ``type``: a finite number in ``[lo, hi]`` (``above``: ``lo`` excluded),
    an int when ``integer``."""

    def parse(text: str) -> float | int:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"want a number, got {text!r}") from None
        ok_low = v > lo if above else v >= lo
        if not math.isfinite(v) or not ok_low or v > hi or (integer and v != int(v)):
            kind = "a whole number" if integer else "a finite number"
            span = f"greater than {lo:g} and at most {hi:g}" if above else f"from {lo:g} to {hi:g}"
            raise argparse.ArgumentTypeError(f"want {kind} {span}, got {text!r}")
        return int(v) if integer else v

    parse.__name__ = name.lstrip("-").replace("-", "_")  # argparse names the type in its message
    return parse


def finite_list(text: str, what: str, *, n: int | None = None, sep: str = ",", bound: float = HUGE) -> list[float]:
    """``text`` as ``sep``-separated finite numbers (``n`` of them when given), each within
    +-``bound``; ValueError with a one-line message otherwise."""
    try:
        vals = [float(v) for v in text.split(sep)]
    except ValueError:
        raise ValueError(f"{what} wants numbers separated by {sep!r}, got {text!r}") from None
    if n is not None and len(vals) != n:
        raise ValueError(f"{what} wants {n} numbers, got {text!r}")
    if not all(math.isfinite(v) and abs(v) <= bound for v in vals):
        raise ValueError(f"{what} wants finite numbers within +-{bound:g}, got {text!r}")
    return vals
