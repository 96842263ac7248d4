"""The workspace's side panel: the text ``ws_keys.panel_text`` builds, repainted line by line, and
the range ``S`` would use at the cursor, which the panel computes itself.

The text builder only reads and records what it wants (``SeedRange.wants``); the panel, once the
cursor has rested on a voxel, runs the computation in a worker of its own and posts
``SeedRangeReady`` (the screen then repaints the panel). No worker touches a widget.
"""

from __future__ import annotations

from ctui.screens.linestatic import LineStatic
from ctui.screens.messages import SeedRangeReady
from ctui.screens.session import Session
from ctui.screens.ws_state import SeedRange

SEED_RANGE_REST_S = 0.15  # the seed range is computed once the cursor stays this long (s) on a voxel


class SidePanel(LineStatic):  # a step repaints only the panel's lines that changed
    DEFAULT_CSS = """
    SidePanel { width: 38; height: 1fr; padding: 0 1; background: $panel; }
    """

    def __init__(self, seed_range: SeedRange, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.seed_range = seed_range
        self._scheduled: object = None  # the key whose computation is timed or running

    def follow(self, session: Session) -> None:
        """Computes the range the text asked for (``seed_range.key``, a (z, y, x, pipeline...) key)
        once the cursor has rested there: a held key steps faster than a range is computed."""
        sr, key = self.seed_range, self.seed_range.key
        if key is None or sr.result is not None or key == self._scheduled:
            return
        self._scheduled = key
        s = session
        from ctui.engine.actions.segment import suggest_range  # the engine loads after the first paint (main thread)

        def work() -> None:  # a thread: filters on the neighbourhood may take a while
            try:
                with s._lock:
                    rc = suggest_range(s.volume, (key[2], key[1], key[0]), pipeline=s.pipeline)
            except Exception:  # off the image, a filter error: the views report it
                return
            if sr.store(key, rc):  # dropped when the cursor moved on meanwhile
                self.post_message(SeedRangeReady())

        def start() -> None:
            if sr.key == key and sr.result is None and self.is_attached:
                self.run_worker(work, thread=True, exclusive=True, group="seed-range", name="seed-range")

        self.set_timer(SEED_RANGE_REST_S, start)
