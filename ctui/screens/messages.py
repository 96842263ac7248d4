"""Textual messages between ctui's workers, screens and the app.

Thread workers never touch widgets: they ``post_message`` one of these to the screen
(or app) that started them (``post_message`` is thread-safe). A screen that has been
closed meanwhile no longer runs its message loop, so a late answer is dropped instead
of updating widgets that are gone (the NoMatches '#ms-status' / '#v3-status' races).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar, dataclass_transform

from textual.message import Message


class JobProgress(Message):
    """A worker's progress: ``label`` with ``done`` of ``total`` (``total`` None: indeterminate);
    ``label`` None hides the progress row."""

    def __init__(self, label: str | None, done: float = 0.0, total: float | None = None) -> None:
        super().__init__()
        self.label = label
        self.done = float(done)
        self.total = None if total is None else float(total)


# The messages below are dataclasses: their fields are the constructor's arguments, in
# order (Textual's Message finishes its set-up in __post_init__); eq=False keeps each
# message equal only to itself, as Textual expects.
_M = TypeVar("_M", bound=type)


@dataclass_transform(eq_default=False)
def event(cls: _M) -> _M:
    """``@dataclass(eq=False)``, spelt so that type checkers see the generated constructor."""
    dataclass(eq=False)(cls)  # in place: the class itself, with its __init__
    return cls


@event
class Status(Message):
    """One line for the screen's status bar."""

    text: str


@event
class JobFailed(Message):
    """A worker failed: ``what`` did not happen because of ``reason`` (shown as an error;
    ``reason`` "cancelled": the user cancelled it)."""

    what: str
    reason: str


@event
class SegmentationFailed(Message):
    """The workspace's segmentation or propagation (``what``) failed because of ``reason``
    ("cancelled": Escape): no proposal."""

    what: str
    reason: str


@event
class SectionsFailed(Message):
    """The sections of object ``oid`` could not be computed (measure screen)."""

    oid: int
    reason: str


@event
class JobFinished(Message):
    """A workspace job (an export...) finished: ``text`` for a notification and the status line."""

    text: str


@event
class StageViewsReady(Message):
    """The pipeline's views (``SliceViews``) of slice ``z`` for the request ``token``."""

    z: int
    token: int
    views: Any


@event
class CellRendered(Message):
    """The 2x2 layout's 3D cell: an RGB ``image`` (None: nothing to show) and its ``caption``."""

    image: Any
    caption: str


@event
class ProposalReady(Message):
    """A segmentation run (``screens.propagation.PropagationRun``) ended with its proposal."""

    run: Any


@event
class MeshesReady(Message):
    """The 3D view's surfaces (object id -> mesh), built in ``dt`` seconds."""

    meshes: dict
    dt: float


@event
class FrameReady(Message):
    """A rendered RGB ``image`` of the 3D view's request ``req``, rendered in ``dt`` seconds."""

    image: Any
    req: int
    dt: float


@event
class FlyFrame(Message):
    """Frame ``i`` of ``n`` of the 3D view's fly-through (request ``req``), rendered in ``dt`` seconds."""

    image: Any
    req: int
    i: int
    n: int
    dt: float


@event
class Saved(Message):
    """A file was written: ``text`` says what and where."""

    text: str


@event
class MeasuredRow(Message):
    """The measure screen's figures (``stats``: a row of the table) of object ``oid``."""

    oid: int
    stats: dict


@event
class SectionsReady(Message):
    """The centreline sections (a ``MeasureResult``) of object ``oid``."""

    oid: int
    result: Any


@event
class AutoReady(Message):
    """The AI first draft (``screens.auto_screen``) ended: ``result`` (an ``actions.auto.AutoResult``)
    over ``snapshot``, the labels it started from."""

    result: Any
    snapshot: Any


class LabelsChanged(Message):
    """The segmentation changed (posted by screens that edit it, to the workspace)."""


class SeedRangeReady(Message):
    """The side panel's seed range at the cursor is computed (``SeedRange`` holds it): repaint the panel."""


class SessionReady(Message):
    """A series or project has loaded: the app opens a workspace on ``session``."""

    def __init__(self, session: Any) -> None:
        super().__init__()
        self.session = session


class LoadFailed(Message):
    """Loading ``path`` failed for ``reasons``."""

    def __init__(self, path: str | None, reasons: list[str], options: dict | None = None) -> None:
        super().__init__()
        self.path = path
        self.reasons = list(reasons)
        self.options = dict(options or {})


@event
class SeriesFound(Message, bubble=False):
    """The open screen's scan of ``path`` ended: the series ``found`` (headers), or ``error`` (a reason)."""

    path: Any
    found: list
    error: str | None


@event
class DriftReady(Message, bubble=False):
    """The drift screen's check ended: ``report`` (``actions.drift``'s report)."""

    report: Any


@event
class Note(Message, bubble=False):
    """A line for the posting screen's own info label (a scan's progress, an empty result); not bubbled."""

    text: str
