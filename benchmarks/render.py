"""Benchmark: ctui's renderer vs VTK's offscreen render window, in one run.

1. A ~1M-triangle mesh (bumpy UV sphere, smooth normals) at 1024x1024: ctui (FXAA,
   4x MSAA, no AA) vs VTK (vtkRenderWindow offscreen, multisampling off and its
   default 8x). Each timed frame changes the camera (azimuth) and includes the
   readback to a numpy (h, w, 3) array; the mesh is uploaded once (both cache it).
2. DVR of a synthetic 256^3 CT volume at 512x512 from an oblique view (ct-bone
   preset): ctui with its defaults, without empty-space skipping, at half resolution,
   and VTK's vtkGPUVolumeRayCastMapper (same size, same view, similar transfer function)
   for reference.

Prints medians, ratios and peak memory. Runs anywhere `pip install -e .[bench]` works
(EGL: Mesa llvmpipe on a CPU-only server, the NVIDIA driver on a GPU machine):

    python benchmarks/render.py [--repeat 7] [--quick]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def bumpy_sphere(n_lat: int = 501, n_lon: int = 1000, radius: float = 80.0):
    """UV sphere with ~2*(n_lat-1)*n_lon triangles and a bumpy surface (mm)."""
    from ctui.engine.core.meshdata import Mesh

    th = np.linspace(0, np.pi, n_lat)
    ph = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    r = radius * (1 + 0.06 * np.sin(7 * T) * np.cos(5 * P) + 0.03 * np.sin(19 * P) * np.sin(T))
    v = np.stack([r * np.sin(T) * np.cos(P), r * np.sin(T) * np.sin(P), r * np.cos(T)], axis=-1).reshape(-1, 3)
    i = np.arange(n_lat - 1)[:, None] * n_lon
    j = np.arange(n_lon)[None, :]
    a = (i + j).ravel()
    b = (i + (j + 1) % n_lon).ravel()
    c = a + n_lon
    d = b + n_lon
    f = np.concatenate([np.c_[a, c, b], np.c_[b, c, d]]).astype(np.int32)
    from ctui.engine.render.gl import vertex_normals

    m = Mesh(v.astype(np.float32), f, object_id=1)
    m.normals = vertex_normals(m.vertices, m.faces)
    return m


def ct_volume(n: int = 256, seed: int = 0) -> np.ndarray:
    """Synthetic CT (HU, int16): air, an elliptic body of soft tissue with noise, a
    spine-like bone column, ribs-like bone rings and two contrast vessels."""
    rng = np.random.default_rng(seed)
    z, y, x = np.ogrid[:n, :n, :n]
    c = (n - 1) / 2
    body = ((x - c) / (0.42 * n)) ** 2 + ((y - c) / (0.32 * n)) ** 2 < 1
    vol = np.full((n, n, n), -1000, np.int16)
    vol[np.broadcast_to(body, vol.shape)] = 40
    spine = ((x - c) / (0.06 * n)) ** 2 + ((y - c - 0.18 * n) / (0.06 * n)) ** 2 < 1
    vol[np.broadcast_to(spine, vol.shape) & ((z % (n // 10)) < n // 13)] = 800
    ring = np.abs(np.sqrt(((x - c) / 0.38) ** 2 + ((y - c) / 0.28) ** 2) - n) < 0.012 * n / 0.3
    ribs = np.broadcast_to(ring, vol.shape) & ((z % (n // 8)) < n // 40)
    vol[ribs] = 650
    for dx in (-0.1, 0.1):
        ves = ((x - c - dx * n) / (0.03 * n)) ** 2 + ((y - c + 0.05 * n) / (0.03 * n)) ** 2 < 1
        vol[np.broadcast_to(ves, vol.shape)] = 300
    vol = vol + rng.normal(0, 12, vol.shape).astype(np.int16)
    return vol


def median_time(fn, repeat: int) -> tuple[float, list[float]]:
    ts = []
    for i in range(repeat):
        t0 = time.perf_counter()
        fn(i)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), ts


def ctui_surface_runner(mesh, size, aa):
    """A callable rendering one frame (camera turned by i * 10 degrees) with readback."""
    from ctui.engine.render import Scene, get_renderer

    r = get_renderer()
    scene = Scene.from_meshes(mesh)
    scene.options.antialias = aa
    scene.camera.elevation = 20
    r.render(scene, size=size)  # upload + compile

    def one(i):
        scene.camera.azimuth = 10.0 * i
        img = r.render(scene, size=size)
        assert img.shape == (size[1], size[0], 3)
    return one


def _vtk_polydata(mesh):
    import vtk
    from vtk.util import numpy_support as ns

    pts = vtk.vtkPoints()
    pts.SetData(ns.numpy_to_vtk(np.ascontiguousarray(mesh.vertices, np.float32), deep=True))
    f = np.asarray(mesh.faces, np.int64)
    cells = vtk.vtkCellArray()
    offsets = np.arange(0, 3 * len(f) + 1, 3, dtype=np.int64)
    cells.SetData(ns.numpy_to_vtkIdTypeArray(offsets, deep=True), ns.numpy_to_vtkIdTypeArray(f.ravel(), deep=True))
    pd = vtk.vtkPolyData()
    pd.SetPoints(pts)
    pd.SetPolys(cells)
    nrm = ns.numpy_to_vtk(np.ascontiguousarray(mesh.normals, np.float32), deep=True)
    nrm.SetName("Normals")
    pd.GetPointData().SetNormals(nrm)
    return pd


def _vtk_window(size, multisamples):
    import vtk

    rw = vtk.vtkRenderWindow()
    rw.SetOffScreenRendering(1)
    if multisamples is not None:
        rw.SetMultiSamples(multisamples)
    rw.SetSize(*size)
    ren = vtk.vtkRenderer()
    ren.SetBackground(0.07, 0.07, 0.09)
    rw.AddRenderer(ren)
    return rw, ren


def _vtk_read(rw, size):
    from vtk.util import numpy_support as ns
    import vtk

    arr = vtk.vtkUnsignedCharArray()
    rw.GetPixelData(0, 0, size[0] - 1, size[1] - 1, 0, arr, 0)  # 0: back buffer, as rendered
    return ns.vtk_to_numpy(arr).reshape(size[1], size[0], 3)[::-1]


def vtk_surface_runner(mesh, size, multisamples):
    import vtk

    rw, ren = _vtk_window(size, multisamples)
    m = vtk.vtkPolyDataMapper()
    m.SetInputData(_vtk_polydata(mesh))
    m.ScalarVisibilityOff()
    a = vtk.vtkActor()
    a.SetMapper(m)
    a.GetProperty().SetColor(0.9, 0.24, 0.24)
    a.GetProperty().SetSpecular(0.35)
    a.GetProperty().SetSpecularPower(40)
    ren.AddActor(a)
    ren.ResetCamera()
    ren.GetActiveCamera().Elevation(20)
    rw.Render()

    def one(i):
        ren.GetActiveCamera().Azimuth(10.0)
        rw.Render()
        img = _vtk_read(rw, size)
        assert img.shape == (size[1], size[0], 3)
    one.window = rw
    one.multisamples = rw.GetMultiSamples()
    return one


def cpu_seconds() -> float:
    """CPU time of this process, all threads (llvmpipe's and VTK's render threads)."""
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def interleaved(runners: dict, repeat: int) -> tuple[dict, dict]:
    """Time each runner ``repeat`` times, alternating between them so that load
    changes on a shared machine hit all of them alike; returns ({name: [wall s]},
    {name: [cpu s]}). CPU time (all threads of this process) is the steadier figure
    on a shared machine; wall time is what a user waits."""
    ts = {k: [] for k in runners}
    cs = {k: [] for k in runners}
    for i in range(repeat):
        for k, fn in runners.items():
            c0 = cpu_seconds()
            t0 = time.perf_counter()
            fn(i)
            ts[k].append(time.perf_counter() - t0)
            cs[k].append(cpu_seconds() - c0)
    return ts, cs


def bench_ctui_dvr(vol, size, repeat, **opts):
    from ctui.engine.render import Scene, SceneVolume, get_renderer

    r = get_renderer()
    scene = Scene(volume=SceneVolume(vol, spacing=(1.0, 1.0, 1.0), modality="CT"), mode="dvr")
    scene.options.preset = "ct-bone"
    for k, v in opts.items():
        setattr(scene.options, k, v)
    scene.camera.azimuth, scene.camera.elevation = 35.0, 25.0
    t0 = time.perf_counter()
    img = r.render(scene, size=size)  # upload + bricks
    first = time.perf_counter() - t0
    def one(i):
        scene.camera.azimuth = 35.0 + 2.0 * i
        img = r.render(scene, size=size)
        assert img.shape == (size[1], size[0], 3)
    c0 = cpu_seconds()
    med, ts = median_time(one, repeat)
    cpu = (cpu_seconds() - c0) / repeat
    return med, ts, first, img, cpu


def bench_vtk_dvr(vol, size, repeat):
    import vtk
    from vtk.util import numpy_support as ns

    from ctui.engine.render.transfer import PRESETS

    rw, ren = _vtk_window(size, 0)
    img = vtk.vtkImageData()
    n = vol.shape
    img.SetDimensions(n[2], n[1], n[0])
    img.GetPointData().SetScalars(ns.numpy_to_vtk(np.ascontiguousarray(vol).ravel(), deep=True))
    mapper = vtk.vtkGPUVolumeRayCastMapper()
    mapper.SetInputData(img)
    ctf = vtk.vtkColorTransferFunction()
    otf = vtk.vtkPiecewiseFunction()
    for v, r_, g, b, a in PRESETS["ct-bone"]["points"]:
        ctf.AddRGBPoint(v, r_, g, b)
        otf.AddPoint(v, a)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(ctf)
    prop.SetScalarOpacity(otf)
    prop.ShadeOn()
    prop.SetInterpolationTypeToLinear()
    v = vtk.vtkVolume()
    v.SetMapper(mapper)
    v.SetProperty(prop)
    ren.AddVolume(v)
    ren.ResetCamera()
    cam = ren.GetActiveCamera()
    cam.Elevation(25)
    cam.Azimuth(35)
    rw.Render()
    def one(i):
        cam.Azimuth(2.0)
        rw.Render()
        _vtk_read(rw, size)
    c0 = cpu_seconds()
    med, ts = median_time(one, repeat)
    cpu = (cpu_seconds() - c0) / repeat
    rw.Finalize()
    return med, ts, cpu


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--quick", action="store_true", help="smaller problem (smoke run)")
    ap.add_argument("--no-vtk", action="store_true")
    args = ap.parse_args()
    from ctui.engine.render import get_renderer

    r = get_renderer()
    print(f"ctui renderer: {r.info['renderer']} | {r.info['version']}")
    print(f"machine: {platform.machine()} {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} "
          "(other processes share the CPUs: compare the interleaved figures, and CPU seconds)")

    n_lat, n_lon = (126, 250) if args.quick else (501, 1000)
    t0 = time.perf_counter()
    mesh = bumpy_sphere(n_lat, n_lon)
    print(f"\n== surfaces: {mesh.n_faces:,} triangles at 1024x1024 (mesh built in {time.perf_counter() - t0:.1f} s)")
    size = (1024, 1024)
    runners = {f"ctui AA={aa}": ctui_surface_runner(mesh, size, aa) for aa in ("fxaa", "msaa", "none")}
    have_vtk = not args.no_vtk
    if have_vtk:
        try:
            import vtk  # noqa: F401
        except ImportError:
            print("  vtk not installed: pip install -e .[bench]")
            have_vtk = False
    if have_vtk:
        for label, ms in (("VTK no MSAA", 0), ("VTK default", None)):
            runners[label] = vtk_surface_runner(mesh, size, ms)
        print(f"  VTK default multisampling: {runners['VTK default'].multisamples}x")
    ts, cs = interleaved(runners, args.repeat)
    res = {k: statistics.median(v) for k, v in ts.items()}
    cres = {k: statistics.median(v) for k, v in cs.items()}
    for k, v in ts.items():
        print(f"  {k:<14} median {res[k]:.3f} s wall, {cres[k]:.3f} s CPU   "
              f"(wall runs: {', '.join(f'{t:.3f}' for t in v)})")
    if have_vtk:
        print("  ratios ctui / VTK, wall (CPU) (goal <= 0.8 with anti-aliasing on):")
        for a in ("fxaa", "msaa", "none"):
            print("    " + "   ".join(f"ctui {a:<4} / {b:<11} = {res[f'ctui AA={a}'] / res[b]:.2f} "
                                     f"({cres[f'ctui AA={a}'] / cres[b]:.2f})"
                                     for b in ("VTK default", "VTK no MSAA")))
        for k in ("VTK no MSAA", "VTK default"):
            runners[k].window.Finalize()
    del mesh

    nv = 96 if args.quick else 256
    t0 = time.perf_counter()
    vol = ct_volume(nv)
    print(f"\n== DVR: {nv}^3 CT volume (int16) at 512x512, oblique view, ct-bone preset "
          f"(volume built in {time.perf_counter() - t0:.1f} s)")
    size = (512, 512)
    dres = {}
    for label, opts in (("default (skipping, early termination, 1 sample/voxel, shading)", {}),
                        ("no empty-space skipping", {"empty_space_skipping": False}),
                        ("half resolution (volume_scale=0.5)", {"volume_scale": 0.5}),
                        ("0.5 samples/voxel", {"samples_per_voxel": 0.5})):
        med, ts, first, img, cpu = bench_ctui_dvr(vol, size, args.repeat, **opts)
        dres[label] = med
        print(f"  ctui {label:<62} median {med:.3f} s wall, {cpu:.3f} s CPU; first frame {first:.2f} s")
    base = dres["default (skipping, early termination, 1 sample/voxel, shading)"]
    print(f"  empty-space skipping speed-up: {dres['no empty-space skipping'] / base:.2f}x; goal <= 0.15 s: "
          f"{'met' if base <= 0.15 else 'NOT met'} ({base:.3f} s)")
    if have_vtk:
        try:
            med, ts, cpu = bench_vtk_dvr(vol, size, args.repeat)
            print(f"  VTK  vtkGPUVolumeRayCastMapper (shade on)   median {med:.3f} s wall, {cpu:.3f} s CPU; "
                  f"ctui/VTK = {base / med:.2f}")
        except Exception as exc:  # noqa: BLE001
            print(f"  VTK volume mapper failed: {exc}")
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}; peak RSS {peak_rss_mb():.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
