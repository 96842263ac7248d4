"""The review of a pending proposal (or of the current object) on the workspace's review strip:
its marked slices (``{`` ``}``), cut at this slice (``C``), accept from the seed to here (``A``)
(:class:`ReviewOwner`, composed by :class:`ctui.screens.workspace.WorkspaceScreen`)."""

from __future__ import annotations

import weakref

from ctui.engine.actions.edit import review
from ctui.screens import planes
from ctui.screens.ws_host import Owner, WorkspaceHost


class ReviewOwner(Owner):
    """What the review strip shows and the review keys; caches the current object's stack and marks."""

    def __init__(self, ws: WorkspaceHost) -> None:
        super().__init__(ws)
        self.object_stack: tuple | None = None  # ((labels version, object), Stack or None)
        self.object_full: tuple | None = None  # (version, object, seg ref, labels ref, revision, whole Stack)
        self.marks_cache: tuple | None = None  # (source, marks)

    # ------------------------------------------------------------------ review of a proposal
    def seed_mask(self, p):
        return self.s.seg.labels[p.start_slice] == p.object_id

    def review_source(self):
        """What the strip reviews: the pending proposal, else the current object when it spans
        three slices or more (``review.Stack``, cached per labels version), else None."""
        if self.ws.pending.proposal is not None:
            return self.ws.pending.proposal
        s = self.s
        key = (self.ws.volumes.version, s.current)
        cache = self.object_stack
        if cache is not None and cache[0] == key:
            return cache[1]
        info = s.seg.objects.get(s.current)
        seeds = list(getattr(info, "seeds", []) or [])
        start = int(seeds[-1][2]) if seeds else None
        seg, full = s.seg, self.object_full  # (version, object, seg, labels, revision, Stack)
        rev = int(getattr(seg, "revision", -1))
        since = None
        if full is not None and full[1] == s.current and full[2]() is seg and full[3]() is seg.labels \
                and hasattr(seg, "changes_since"):
            since = seg.changes_since(full[4])
            if since is not None and self.ws.volumes.version - full[0] > rev - full[4]:
                since = None  # more versions than journalled edits: the labels changed some other way
        # after brush/erase/undo/redo only the slices they touched are read again (a whole 1,000-slice scan: 2.3 s)
        whole = (review.of_labels(seg.labels, s.current, start) if since is None
                 else review.restack(full[5], seg.labels, s.current, since[1], start))
        self.object_full = (self.ws.volumes.version, s.current, weakref.ref(seg), weakref.ref(seg.labels), rev, whole)
        stack = whole if whole.masks and max(whole.masks) - min(whole.masks) >= 2 else None
        self.object_stack = (key, stack)
        return stack

    def review_marks(self) -> list:
        src = self.review_source()
        if src is None:
            return []
        cache = self.marks_cache
        if cache is not None and cache[0] is src:
            return cache[1]
        seed = self.seed_mask(src) if src is self.ws.pending.proposal else None
        info = self.s.seg.objects.get(self.s.current) if seed is None else None  # an accepted object: its leaks
        leaks = list(getattr(src, "leak_entries", None) or (getattr(info, "settings", None) or {}).get("leaks", []))
        found = review.marks(src, spacing_yx=(self.s.volume.spacing[1], self.s.volume.spacing[2]), seed_mask=seed, leaks=leaks)
        self.marks_cache = (src, found)
        return found

    def update_strip(self) -> None:
        """The strip shows the proposal, or (on a terminal 30 rows high or more) the current object."""
        strip = self.ws.review_strip()
        if strip is None:
            return
        p = self.ws.pending.proposal
        if p is None and not self.ws.viewstate.painted:
            # an opened project's object is reviewed once the workspace is on screen (its slices' outlines
            # and marks take 0.1-0.4 s for a large object)
            self.ws.viewstate.painted = True
            self.ws.call_after_refresh(self.update_strip)
            strip.set_class(False, "on")
            return
        src = p if p is not None else (self.review_source() if self.ws.size.height >= 30 else None)
        if src is None:
            strip.set_class(False, "on")
            return
        seed_area = int(self.seed_mask(p).sum()) if p is not None else 0
        prof = review.profile(src, self.s.shape[0], seed_area=seed_area)
        marks = [m.z for m in self.review_marks()]
        leaked = [m.z for m in self.review_marks() if "leak" in m.kind]
        keys = "} { marks, C cut, A accept to here" if p is not None else "} { marks"
        hint = f"{len(marks)} mark{'s' if len(marks) != 1 else ''}: {keys}" if marks else ("no marks" if p is not None else "")
        strip.set_data(prof, marks, self.s.z, src.start_slice, hint=f"{'proposal' if p is not None else 'object'} · {hint}",
                       leaked=leaked, limits=self.s.limits.slices)
        strip.set_class(True, "on")

    def go_slice(self, z: int) -> None:
        s = self.s
        s.z = int(z)
        s.clamp()
        if not self.ws.viewstate.ortho_mode:  # the strip's axis is the file's slices: show them
            s.plane = planes.slice_plane(s.volume)
        self.refresh_view()
        why = {m.z: m.why for m in self.review_marks()}.get(s.z)
        if why and self.ws.pending.proposal is not None:
            self.set_status(self.mark_status(s.z, why))  # at a leak's entry: the cursor on the voxel to click
        elif why:
            self.set_status(f"Slice {s.z}: {why}. t: keep the island / scissors on this slice; {{ }} other marks")

    def action_mark(self, step: int) -> None:
        if self.review_source() is None:
            self.app.notify("Nothing to review: p propagates (or draw the object on three slices or more)", timeout=2)
            return
        z = review.next_mark(self.review_marks(), self.s.z, step)
        if z is None:
            self.app.notify(f"No marked slice {'after' if step > 0 else 'before'} slice {self.s.z}", timeout=2)
            return
        self.go_slice(z)

    def _proposal_to_review(self, none: str):
        """The pending proposal when one waits and no segmentation runs; else None (``none``:
        the notification when there is no proposal)."""
        p = self.ws.pending.proposal
        if p is None:
            self.app.notify(none, timeout=2)
            return None
        return None if self.ws.edit.busy() else p

    def action_cut_here(self) -> None:
        p = self._proposal_to_review("No proposal to cut: p propagates")
        if p is None:
            return
        z, start = self.s.z, int(p.start_slice)
        marked = z != start and z in {m.z for m in self.review_marks()}
        if marked:  # a mark is where it leaks (the area jumps, the centre moves): keep the slice before it
            z += -1 if z > start else 1
        cut = review.cut_at(p, z, seed_mask=self.seed_mask(p))
        self.ws.pending.replace(cut)
        rng = cut.slices
        where = f"before the marked slice {self.s.z}, kept to {z}" if marked else f"at slice {z}"
        self.set_status(f"Cut {where}: {cut.voxels} voxels (was {p.voxels}), "
                        f"{'slices %d..%d' % rng if rng else 'nothing left'}; a accepts, x rejects")
        self.refresh_view()

    def action_accept_to_here(self) -> None:
        p = self._proposal_to_review("No pending proposal")
        if p is None:
            return
        self.ws.pending.replace(review.keep_to(p, self.s.z, seed_mask=self.seed_mask(p)))
        self.ws.segment.accept()

    def mark_status(self, z: int, why: str) -> str:
        """The status line at the pending proposal's marked slice ``z``. Where a leak enters, the cursor goes to
        the voxel its flag gives as a background seed: ``B`` places it there, ``p`` segments again (no typing)."""
        leaks = getattr(self.ws.pending.proposal, "leak_entries", None) or []
        click = next((lk["click"] for lk in leaks if int(lk.get("slice", -1)) == z and "click" in lk), None)
        if click is None:
            return f"Slice {z}: {why}. C cuts here, A accepts from the seed to here, {{ }} other marks"
        s = self.s
        s.x, s.y, s.z = (int(v) for v in click)
        s.clamp()
        self.refresh_view()
        return (f"Slice {z}: {why}. The cursor is on that voxel: B makes it a background seed, then p segments "
                "again (or C cuts here)")
