"""What a loader assumed in place of the file: :class:`Assumption`.

A loader that replaces a value it could not trust (a voxel size, an orientation), drops
slices it could not decode or changes voxel values (NaN set, values clipped) says so with
an :class:`Assumption` in ``Volume.warnings``. It *is* the warning text (a ``str``), so every
list, JSON report and screen that shows warnings shows it, and it carries its ``kind``
(one of :data:`KINDS`) and, for dropped slices, how many of how many, so that
``Volume.assumptions`` lists them typed and :func:`check_share` refuses a volume past a
stated share (:data:`MAX_DROPPED_SHARE`). ``actions.opened`` adds every assumption to the
notes each command prints (text and ``--json``), the TUI shows them in its status line.
"""

from __future__ import annotations

from typing import Any, Iterable

#: spacing: a voxel size replaced (1 mm, or a default); slices: slices dropped (not
#: decoded); orientation: an orientation replaced or repaired; values: voxel values changed
KINDS = ("spacing", "slices", "orientation", "values", "origin")

#: more than this share of a series' slices dropped (undecodable) -> refused
MAX_DROPPED_SHARE = 0.25


class Assumption(str):
    """A loader's warning that it assumed something (a ``str``: the text the user reads).

    ``kind``: one of :data:`KINDS`; ``count``/``total``: slices dropped of slices (kind
    "slices"), else 0."""

    kind: str
    count: int  # type: ignore[assignment]  # the slices dropped: hides str.count on purpose (a field since the first loader)
    total: int

    def __new__(cls, text: str, kind: str, count: int = 0, total: int = 0) -> "Assumption":
        if kind not in KINDS:
            raise ValueError(f"unknown assumption kind {kind!r}")
        obj = super().__new__(cls, text)
        obj.kind, obj.count, obj.total = kind, int(count), int(total)
        return obj

    def __reduce__(self) -> tuple:  # pickles (worker processes) keep the kind
        return (Assumption, (str(self), self.kind, self.count, self.total))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kind": self.kind, "text": str(self)}
        if self.total:
            d.update(count=self.count, total=self.total)
        return d


def assumptions(warnings: Iterable[Any]) -> list[Assumption]:
    """The :class:`Assumption` items of a warnings list, in order, each once."""
    out: list[Assumption] = []
    for w in warnings or ():
        if isinstance(w, Assumption) and w not in out:
            out.append(w)
    return out


def note_of(a: Assumption) -> str:
    """The line a command prints for ``a`` ("assumed (spacing): ...")."""
    return f"assumed ({a.kind}): {a}"


def dropped_share_error(count: int, total: int) -> str | None:
    """The one-line refusal when ``count`` of ``total`` slices dropped is past the share, else None."""
    if total and count / total > MAX_DROPPED_SHARE:
        return (f"{count} of {total} slices could not be decoded (more than {MAX_DROPPED_SHARE:.0%}): refused; "
                "the surface and volumes would be of another object")
    return None
