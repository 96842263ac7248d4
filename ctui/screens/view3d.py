"""The 3D screen (``r``): object surfaces (marching cubes / smoothed mask surfaces, or
contour connecting) rendered offscreen by ``ctui.engine.render`` on the renderer's
own thread, shown at the panel's pixel size. The keyboard never blocks: each request
is a Future; a newer request supersedes older ones (their images are dropped)."""

from __future__ import annotations

import copy
import time

import numpy as np
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.screen import Screen
from textual.widgets import Static

from ctui.engine import render
from ctui.engine.actions import defaults
from ctui.engine.actions.formats import output_name
from ctui.engine.actions.mesh import label_meshes
from ctui.engine.core.atomic import check_output
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.rendermodes import MODES, VOLUME_MODES
from ctui.engine.actions.render import centreline  # the function the fly-through of ctui render uses
from ctui.screens.dialogs import PromptScreen
from ctui.screens.guard import GuardMixin
from ctui.screens.imageview import ImageView
from ctui.screens.session import Session
from ctui.screens.keybar import KeyBar
from ctui.screens.keytable import keys
from ctui.screens.messages import FlyFrame, FrameReady, JobFailed, MeshesReady, Saved, Status
from ctui.screens.session import safe_cwd

METHODS = defaults.MESH_METHODS  # the surface methods the c key cycles through


def build_meshes(session: Session, method: str, *, progress=None) -> dict:
    """{object_id: Mesh} of the session's objects with the chosen surface method, by
    :func:`ctui.engine.actions.mesh.label_meshes` (what ``ctui mesh`` of a project does)."""
    labels = session.labels()
    if labels is None or not labels.any():
        return {}
    ids = [int(i) for i in np.flatnonzero(np.bincount(labels.ravel(), minlength=256)[1:]) + 1]
    return label_meshes(labels, Geometry.of(session.volume), ids, method=method, progress=progress)


class View3DScreen(GuardMixin, Screen):
    DEFAULT_CSS = """
    View3DScreen #v3-body { height: 1fr; }
    View3DScreen #v3-info { width: 30; padding: 0 1; background: $panel; }
    View3DScreen #v3-info.hidden { display: none; }
    View3DScreen #v3-status { height: 1; background: $boost; padding: 0 1; }
    """
    BINDINGS = keys("""
    left              orbit(-15,0)  Orbit left 15°                          hidden
    right             orbit(15,0)   Orbit right 15°                         hidden
    up                orbit(0,15)   Orbit up 15°                            hidden
    down              orbit(0,-15)  Orbit down 15°                          hidden
    shift+left        light(-15,0)  Light left                              hidden
    shift+right       light(15,0)   Light right                             hidden
    shift+up          light(0,15)   Light up                                hidden
    shift+down        light(0,-15)  Light down                              hidden
    plus,equals_sign  zoom(1.25)    Zoom in 3D                              hidden
    minus             zoom(0.8)     Zoom out 3D                             hidden
    m                 mode          Mode: surface/wire/transparent/MIP/DVR
    c                 method        Contours/MC
    S                 shadows       Shadows                                 hidden
    p                 slice_plane   Slice plane                             hidden
    s                 save          Save PNG
    t                 turntable     Turntable
    f                 fly           Fly through object
    F                 fly_save      Save fly-through GIF                    hidden
    backslash         toggle_info   Info panel on/off                       hidden
    escape,r          close         Back
    """)

    def __init__(self, session, *, image=None) -> None:
        """image: a fixed RGB image to show instead of rendering (snapshot tests)."""
        super().__init__()
        self.s = session
        self.mode = "surface"
        self.method = METHODS[0]
        self.meshes: dict | None = None
        self.scene: render.Scene | None = None
        self.fixed_image = image
        self._req = 0
        self.last_image = None
        self.render_times: list[float] = []
        self.shown_requests: list[int] = []
        self.fly_frames_shown = 0
        self._flying = False
        self._busy_since: tuple[float, str] | None = None

    def compose(self) -> ComposeResult:
        with Horizontal(id="v3-body"):
            yield ImageView(id="v3-view")
            yield Static(id="v3-info")
        yield Static("", id="v3-status")
        yield KeyBar()  # wraps at 80 columns instead of cutting the last keys

    def on_mount(self) -> None:
        # under 100 columns (80x24) the view takes the whole width; \ shows the info panel
        self.query_one("#v3-info").set_class(self.app.size.width < 100, "hidden")
        if self.fixed_image is not None:
            self.query_one(ImageView).set_image(self.fixed_image, token="fixed")
            self._info()
            return
        self._info()
        self.set_interval(0.5, self._tick)
        self.prepare_meshes()

    def action_toggle_info(self) -> None:
        info = self.query_one("#v3-info")
        info.set_class(not info.has_class("hidden"), "hidden")
        self.call_after_refresh(self.on_resize)

    def on_resize(self) -> None:
        if self.scene is not None:
            self.request_render()

    # ------------------------------------------------------------------ info
    def _status(self, text: str) -> None:
        self.query_one("#v3-status", Static).update(text)

    def _info(self) -> None:
        lines = ["[b]3D view[/b]", f"mode    {self.mode}", f"surface {self.method}"]
        if self.scene is not None:
            c, lt = self.scene.camera, self.scene.light
            lines += [f"azimuth {c.azimuth:g}°", f"elev.   {c.elevation:g}°", f"zoom    {c.zoom:.2f}",
                      f"light   {lt.azimuth:g}°, {lt.elevation:g}°",
                      f"shadows {'on' if self.scene.options.shadows else 'off'}",
                      f"slice   {'z ' + str(self.scene.options.slice_plane.index) if self.scene.options.slice_plane else 'off'}"]
        if self.meshes:
            lines.append("")
            lines.append("[b]Objects[/b]")
            for oid, m in sorted(self.meshes.items()):
                try:
                    vol = m.volume_mm3() / 1000.0
                except Exception:
                    vol = float("nan")
                lines.append(f" {oid}: {len(m.faces)} tris, {vol:.1f} ml")
        lines += ["", "[dim]arrows orbit 15°", "+/- zoom, shift+arrows light", "m mode, c method, S shadows, p slice",
                  "s PNG, t turntable", "f fly through (f stops)", "F fly-through GIF", "Esc back[/dim]"]
        self.query_one("#v3-info", Static).update("\n".join(lines))

    # ------------------------------------------------------------------ meshes
    @work(thread=True, exclusive=True, group="meshes")
    def prepare_meshes(self) -> None:
        t0 = time.perf_counter()
        self._busy_since = (t0, f"Building surfaces ({self.method})")  # the ticker says how long, every 0.5 s

        def progress(done, total, message=""):
            self._busy_since = (t0, f"Building surfaces ({self.method}): {message or ''} {done:g}/{total:g}")

        try:
            meshes = build_meshes(self.s, self.method, progress=progress)
        except Exception as exc:
            self.post_message(JobFailed("Surfaces", str(exc)))
            meshes = {}
        self.post_message(MeshesReady(meshes, time.perf_counter() - t0))

    def _meshes_ready(self, meshes: dict, dt: float) -> None:
        self.meshes = meshes
        try:
            scene = render.Scene.from_meshes(list(meshes.values()))
            scene.options.show_surfaces = True
        except CtuiError as exc:
            self.app.notify(str(exc), severity="error")
            return
        if self.scene is not None:  # keep the camera and light when switching methods
            scene.camera, scene.light, scene.options = self.scene.camera, self.scene.light, self.scene.options
        self.scene = scene
        if not meshes and self.mode not in VOLUME_MODES:
            self.mode = "mip"
            self.app.notify("No objects yet: showing the volume (MIP); segment objects in the workspace", timeout=5)
        self._status(f"{len(meshes)} surface(s) in {dt:.2f} s")
        self._info()
        self.request_render()

    # ------------------------------------------------------------------ rendering
    def request_render(self) -> None:
        if self.scene is None:
            return
        self._req += 1
        self.scene.mode = self.mode
        self.scene.options.window = tuple(self.s.window)
        # the volume only in volume modes: surfaces alone frame the objects, not the whole series
        need_volume = self.mode in VOLUME_MODES or not self.meshes or self.scene.options.slice_plane is not None
        self.scene.set_volume(self.s.volume if need_volume else None)
        scene = self.scene.snapshot() if hasattr(self.scene, "snapshot") else copy.deepcopy(self.scene)
        size = self.query_one(ImageView).target_pixels()
        self._render_worker(scene, size, self._req)

    @work(thread=True, exclusive=True, group="render")
    def _render_worker(self, scene, size, req: int) -> None:
        t0 = time.perf_counter()
        try:
            fut = render.get_renderer().submit(scene, size)
            while True:
                try:
                    img = fut.result(timeout=0.1)
                    break
                except TimeoutError:
                    if req != self._req:  # superseded: drop it (the renderer finishes on its thread)
                        return
        except Exception as exc:
            msg = str(exc)
            self.post_message(JobFailed("3D render", msg))
            return
        self.post_message(FrameReady(img, req, time.perf_counter() - t0))

    # ------------------------------------------------------------------ messages from the workers
    @on(Status)
    def _status_msg(self, msg: Status) -> None:
        self._status(msg.text)

    @on(JobFailed)
    def _failed(self, msg: JobFailed) -> None:
        self._busy_since = None
        self._status(f"{msg.what} failed: {msg.reason}")
        self.app.notify(f"{msg.what}: {msg.reason}", severity="error", timeout=10)

    @on(MeshesReady)
    def _meshes_msg(self, msg: MeshesReady) -> None:
        self._busy_since = None
        self._meshes_ready(msg.meshes, msg.dt)

    @on(FrameReady)
    def _frame_msg(self, msg: FrameReady) -> None:
        self._show(msg.image, msg.req, msg.dt)

    @on(FlyFrame)
    def _fly_msg(self, msg: FlyFrame) -> None:
        self._show_fly(msg.image, msg.req, msg.i, msg.n, msg.dt)

    @on(Saved)
    def _saved_msg(self, msg: Saved) -> None:
        self.app.notify(f"Saved {msg.text}")
        self._status(f"Saved {msg.text}")

    def _tick(self) -> None:
        """While surfaces are built: what is happening and for how long (never a static message)."""
        busy = self._busy_since
        if busy is not None:
            self._status(f"{busy[1]} ... {time.perf_counter() - busy[0]:.1f} s")

    def _show(self, img, req: int, dt: float) -> None:
        if req != self._req:
            return  # a newer request is on its way
        self.last_image = img
        self.render_times.append(dt)
        self.shown_requests.append(req)
        self.query_one(ImageView).set_image(img, token=("3d", req))
        self._status(f"{self.mode}: {img.shape[1]}x{img.shape[0]} px in {dt * 1000:.0f} ms")

    # ------------------------------------------------------------------ keys
    def action_orbit(self, da: float, de: float) -> None:
        if self.scene is None:
            return
        c = self.scene.camera
        c.azimuth = (c.azimuth + da) % 360
        c.elevation = max(-90.0, min(90.0, c.elevation + de))
        self._info()
        self.request_render()

    def action_light(self, da: float, de: float) -> None:
        if self.scene is None:
            return
        lt = self.scene.light
        lt.azimuth = (lt.azimuth + da + 180) % 360 - 180
        lt.elevation = max(-90.0, min(90.0, lt.elevation + de))
        self._info()
        self.request_render()

    def action_zoom(self, f: float) -> None:
        if self.scene is None:
            return
        self.scene.camera.zoom = max(0.1, min(50.0, self.scene.camera.zoom * f))
        self._info()
        self.request_render()

    def action_mode(self) -> None:
        i = MODES.index(self.mode) if self.mode in MODES else -1
        self.mode = MODES[(i + 1) % len(MODES)]
        self._info()
        self.request_render()

    def action_method(self) -> None:
        self.method = METHODS[(METHODS.index(self.method) + 1) % len(METHODS)]
        self._info()
        self.prepare_meshes()

    def action_shadows(self) -> None:
        if self.scene is None:
            return
        self.scene.options.shadows = not self.scene.options.shadows
        self._info()
        self.request_render()

    def action_slice_plane(self) -> None:
        """Show the current CT slice in place inside the 3D view (or hide it)."""
        if self.scene is None:
            return
        opts = self.scene.options
        if opts.slice_plane is None:
            opts.slice_plane = render.SlicePlane(axis="z", index=int(self.s.z))
            cam = self.scene.camera
            if abs(cam.elevation) < 15.0:
                # an axial plane seen edge-on is an invisible line: look at it from above
                cam.elevation = 30.0
                self.app.notify("Slice plane: camera raised to 30° so the axial slice shows", timeout=3)
        else:
            opts.slice_plane = None
        self._info()
        self.request_render()

    def _ask_path(self, title: str, tag: str, suffix: str, what: str, write) -> None:
        """Prompt for an output path (default ``<input stem>-<tag><suffix>`` in the folder ctui
        started from), then ``write(path)`` in a worker; ``what`` names the file in messages."""
        if self.scene is None:
            return

        def done(path: str | None) -> None:
            if path and path.strip():
                self._save_worker(what, path.strip(), write)

        default = safe_cwd() / output_name(self.s.project_path or self.s.source_path, suffix, tag=tag)
        self.app.push_screen(PromptScreen(title, str(default)), done)

    @work(thread=True, group="save")
    def _save_worker(self, what: str, path: str, write) -> None:
        self.post_message(Status(f"Writing {what} {path} ..."))
        try:
            check_output(path, inputs=[self.s.source_path, self.s.project_path], label=f"the {what}")
            write(path)
        except Exception as exc:
            self.post_message(JobFailed(f"{what.capitalize()} not saved", str(exc)))
            return
        self.post_message(Saved(path))

    def _scene_now(self):
        scene = self.scene.snapshot()
        scene.mode = self.mode
        return scene

    def action_save(self) -> None:
        self._ask_path("Save the 3D view as PNG", "3d", ".png", "PNG", self._write_png)

    def _write_png(self, path: str) -> None:
        render.save_png(path, render.get_renderer().submit(self._scene_now(), (1024, 1024)).result())

    def action_turntable(self) -> None:
        self._ask_path(f"Turntable animation ({defaults.TURNTABLE_FRAMES} frames, GIF)", "turntable", ".gif",
                       "turntable", self._write_turntable)

    def _write_turntable(self, path: str) -> None:
        render.save_turntable(path, self._scene_now(), defaults.TURNTABLE_FRAMES, (384, 384))

    # ------------------------------------------------------------------ fly-through
    FLY_FRAMES = defaults.FLY_FRAMES

    def _fly_path(self):
        """Centreline (m, 3) mm of the workspace's current object, or raise CtuiError."""
        labels = self.s.labels()
        oid = int(self.s.current)
        if labels is None or not (labels == oid).any():
            raise CtuiError(f"object {oid} is empty: fill and propagate it first")
        v = self.s.volume
        path = centreline(labels == oid, spacing=v.spacing, origin=v.origin,
                                               direction=v.direction)
        if path is None or len(path) < 2:
            raise CtuiError(f"no centreline through object {oid}")
        return path

    def _fly_scene(self):
        """The current scene for a flight inside the surfaces: no volume, no slice plane
        (volume modes fall back to surfaces)."""
        scene = self.scene.snapshot()
        scene.mode = "surface" if self.mode in VOLUME_MODES else self.mode
        scene.set_volume(None)
        scene.options.slice_plane = None
        return scene

    def action_fly(self) -> None:
        """Endoscopic fly-through along the current object's centreline, frame by frame
        in the panel; f again (or any other view change) stops it."""
        if self.scene is None:
            return
        self._req += 1
        if self._flying:
            self._flying = False
            self._status("Fly-through stopped")
            return
        self._flying = True
        self.fly_frames_shown = 0
        scene = self._fly_scene()
        self._fly_worker(scene, self.query_one(ImageView).target_pixels(), self._req)

    @work(thread=True, exclusive=True, group="render")
    def _fly_worker(self, scene, size, req: int) -> None:
        try:
            self.post_message(Status("Centreline of the current object ..."))
            path = self._fly_path()
            cams = render.flythrough_cameras(path, self.FLY_FRAMES)
            for i, cam in enumerate(cams):
                if req != self._req:
                    return
                t0 = time.perf_counter()
                img = render.get_renderer().submit(render.flythrough_scene(scene, cam), size).result()
                self.post_message(FlyFrame(img, req, i + 1, len(cams), time.perf_counter() - t0))
        except Exception as exc:
            self.post_message(JobFailed("3D render", str(exc)))
        finally:
            if req == self._req:
                self._flying = False

    def _show_fly(self, img, req: int, i: int, n: int, dt: float) -> None:
        if req != self._req:
            return
        self.last_image = img
        self.fly_frames_shown = i
        self.query_one(ImageView).set_image(img, token=("fly", req, i))
        self._status(f"fly-through frame {i}/{n} ({dt * 1000:.0f} ms); f stops, F saves a GIF")

    def action_fly_save(self) -> None:
        self._ask_path(f"Fly-through animation ({self.FLY_FRAMES} frames, GIF)", "flythrough", ".gif", "fly-through",
                       self._write_flythrough)

    def _write_flythrough(self, path: str) -> None:
        render.save_flythrough(path, self._fly_scene(), self._fly_path(), self.FLY_FRAMES, (384, 384))

    def action_close(self) -> None:
        self._req += 1  # drop anything in flight
        self.app.pop_screen()
