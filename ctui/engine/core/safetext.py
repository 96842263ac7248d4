"""Text that came from a file, made safe to print or to put in a CSV cell.

A DICOM ``SeriesDescription``, a SEG ``SegmentLabel``, an RTSTRUCT ``ROIName``, an object
name in a project or a header value in an error message is attacker-controlled text:
printed raw, an ``ESC ] 52`` sequence writes the user's clipboard (xterm, kitty, iTerm2,
tmux) and ``ESC [ 2 J`` clears the screen. :func:`printable` escapes every control
character (C0, DEL, C1, and the Unicode bidirectional overrides that reorder what is
shown) as ``\\xNN`` / ``\\uNNNN``. :func:`csv_cell` neutralises a spreadsheet formula
(OWASP's rule: a cell starting with ``= + - @``, tab or carriage return gets a leading
``'``).
"""

from __future__ import annotations

import re
from typing import Any

# C0 (but tab/newline when allowed), DEL, C1, bidi embeddings/overrides/isolates, line/paragraph separators
# + lone surrogates \udc80-\udcff: the bytes of a file name that are not UTF-8 (os.fsdecode's
# surrogateescape), written back raw by a surrogateescape stream: a 0x9b byte is C1 CSI
_CONTROL = re.compile("[\x00-\x08\x0a-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\udc80-\udcff]")
_CONTROL_KEEP_LINES = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\udc80-\udcff]")
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _escape(m: re.Match) -> str:
    c = ord(m.group(0))
    if 0xDC80 <= c <= 0xDCFF:  # an undecodable byte of a file name: shown as that byte
        c -= 0xDC00
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def printable(text: Any, *, keep_newlines: bool = False) -> str:
    """``str(text)`` with every control character escaped (``"\\x1b"`` for ESC).

    ``keep_newlines``: leave ``\\n`` (and tab) as they are, for a block of the program's own
    lines that embeds file text; the default (one-line text from a file) escapes them too.
    Tab is always kept.
    """
    s = text if isinstance(text, str) else str(text)
    return (_CONTROL_KEEP_LINES if keep_newlines else _CONTROL).sub(_escape, s)


def csv_cell(value: Any) -> Any:
    """``value`` safe for a spreadsheet: a string starting with ``= + - @``, tab or CR
    that is not a plain number gets a leading ``'`` (numbers pass unchanged), and control
    characters are escaped."""
    if not isinstance(value, str):
        return value
    if value.startswith(_FORMULA_START):
        try:
            float(value)
        except ValueError:
            return "'" + printable(value)
        return value
    return printable(value)
