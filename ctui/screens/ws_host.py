"""What the workspace's owners need from the screen that composes them.

The slice workspace (:class:`ctui.screens.workspace.WorkspaceScreen`) is one screen composed of
owners, plain objects each owning one part of its state and its actions: navigation and views
(:class:`ctui.screens.ws_keys.NavOwner`), label edits (:class:`ctui.screens.ws_edit.EditOwner`),
the 3D edit tools (:class:`ctui.screens.ws_tools.ToolOwner`), the mouse
(:class:`ctui.screens.ws_mouse.MouseOwner`), the review of a proposal
(:class:`ctui.screens.ws_review.ReviewOwner`), the vessel tool
(:class:`ctui.screens.vessel_tool.VesselOwner`) and the segmentation runs
(:class:`ctui.screens.propagation.SegmentRunner`). Each receives the screen as a
:class:`WorkspaceHost`, the declared interface below (the type checker holds the screen to it), and
reaches the other owners through it. An owner's ``action_<name>`` methods are the screen's key
actions ``<name>``: the screen's one Textual action ``do`` runs them by name
(:func:`ctui.screens.keytable.keys` with ``via="do"`` writes the bindings).

Workers never touch widgets: they post the typed messages of :mod:`ctui.screens.messages` to the
screen, whose one handler gives each to its owner.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Protocol

from textual.message import Message
from textual.worker import Worker

if TYPE_CHECKING:  # annotations only (no import at run time: the owners import this module)
    from textual.app import App
    from textual.geometry import Size
    from textual.widget import Widget

    from ctui.screens.imageview import ImageView
    from ctui.screens.session import Session
    from ctui.screens.strip import ReviewStrip
    from ctui.screens.vessel_tool import VesselOwner
    from ctui.screens.ws_edit import EditOwner
    from ctui.screens.ws_jobs import JobRunner
    from ctui.screens.ws_keys import NavOwner
    from ctui.screens.ws_mouse import MouseOwner
    from ctui.screens.ws_review import ReviewOwner
    from ctui.screens.ws_segment import SegmentRunner
    from ctui.screens.ws_state import EditTools, Jobs, ObjectVolumes, ProposalState, SeedRange, ViewState
    from ctui.screens.ws_tools import ToolOwner


class RunHost(Protocol):
    """What a worker's run sees of the screen that started it: the session it reads, and a message
    box (thread-safe ``post_message``; ``is_attached`` False once the screen has gone)."""

    s: Session

    @property
    def is_attached(self) -> bool: ...

    def post_message(self, message: Message) -> bool: ...


class WorkspaceHost(Protocol):
    """The screen as its owners see it: the session, the workspace's state, its owners, and the few
    things only a screen does (show progress and status, repaint, notify, post a message, run a worker)."""

    s: Session
    viewstate: ViewState
    edit_tools: EditTools
    jobs: Jobs
    pending: ProposalState
    volumes: ObjectVolumes
    seed_range: SeedRange
    # the owners
    nav: NavOwner
    edit: EditOwner
    tools: ToolOwner
    mouse: MouseOwner
    review: ReviewOwner
    vessel: VesselOwner
    segment: SegmentRunner
    work: JobRunner

    @property
    def app(self) -> App[Any]: ...

    @property
    def size(self) -> Size: ...

    @property
    def is_attached(self) -> bool: ...

    @property
    def main_view(self) -> ImageView: ...

    # what the screen shows
    def set_status(self, msg: str) -> None: ...

    def show_progress(self, label: str | None, done: float = 0, total: float = 100) -> None: ...

    def refresh_view(self) -> None: ...

    def repaint_cursor(self) -> None: ...

    def update_panel(self) -> None: ...

    def set_layout(self, *, grid: bool = False, ortho: bool = False) -> None: ...

    def request_3d(self) -> None: ...

    def labels_changed(self) -> None: ...

    def targets(self) -> list[tuple[str, str, ImageView]]: ...

    def view_center(self, plane: str | None = None) -> tuple[float, float]: ...

    def review_strip(self) -> ReviewStrip | None: ...

    def action_do(self, name: str, args: tuple = ()) -> None: ...

    # Textual's, as the screen has them
    def notify(self, message: str, *, title: str = "", severity: Any = "information", timeout: float | None = None,
               markup: bool = True) -> None: ...

    def post_message(self, message: Message) -> bool: ...

    def run_worker(self, work: Any, name: str | None = "", group: str = "default", description: str = "",
                   exit_on_error: bool = True, start: bool = True, exclusive: bool = False,
                   thread: bool = False) -> Worker[Any]: ...

    def call_later(self, callback: Callable[..., Any], *args: Any, **kwargs: Any) -> bool: ...

    def set_timer(self, delay: float, callback: Any = None, *, name: str | None = None, pause: bool = False) -> Any: ...

    def call_after_refresh(self, callback: Callable[..., Any], *args: Any, **kwargs: Any) -> bool: ...

    def get_widget_at(self, x: int, y: int) -> tuple[Widget, Any]: ...


class Owner:
    """An owner of part of the workspace: ``ws`` is the screen (a :class:`WorkspaceHost`). The
    properties and helpers below are the host's, spelt short (``self.s`` for ``self.ws.s``)."""

    def __init__(self, ws: WorkspaceHost) -> None:
        self.ws = ws

    @property
    def s(self) -> Session:
        return self.ws.s

    @property
    def app(self) -> App[Any]:
        return self.ws.app

    def set_status(self, msg: str) -> None:
        self.ws.set_status(msg)

    def refresh_view(self) -> None:
        self.ws.refresh_view()

    def update_panel(self) -> None:
        self.ws.update_panel()

    def work_failed(self, what: str, reason: str) -> None:
        """A worker's failure, once its owner has said the worker ended: the progress bar goes, and
        an error notification ("cancelled": the status line says nothing changed)."""
        self.ws.show_progress(None)
        if reason == "cancelled":
            self.set_status(f"{what} cancelled: nothing changed")
            return
        self.app.notify(f"{what} failed: {reason}", severity="error", timeout=10)

    def actions(self) -> dict[str, Callable[..., Any]]:
        """This owner's key actions: ``action_<name>`` methods by ``<name>``."""
        return {n[len("action_"):]: getattr(self, n) for n in dir(type(self)) if n.startswith("action_")}
