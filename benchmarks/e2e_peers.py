"""``benchmarks/end_to_end.py --peers`` (issue 40): every whole command beside the script a user
would write instead, in one run, fresh processes, ctui and peer alternating run by run, warm
(the default numba cache, filled first) and cold (an empty ``NUMBA_CACHE_DIR`` before each
run: a fresh install), medians of ``--repeat``; prints each ratio ctui / peer (goal <= 1.0
warm, <= 1.5 cold).

Rows (the big series is ``end_to_end.py``'s CT-like DICOM series, ``--shape``; the kidney is
the TotalSegmentator abdomen written as DICOM, seeded at the right kidney's deepest voxel):

* render: ``ctui render BIG.stl --size 1024x1024`` (the big series' surface at ``--level``) vs
  VTK: STL reader + smooth normals + an offscreen render window (EGL/OSMesa) + PNG writer;
* measure: ``ctui measure KIDNEY.ctui`` vs scikit-image marching cubes of the NIfTI mask + VTK
  mass properties (volume, area) + the voxel volume;
* segment: ``ctui segment KIDNEY --seed --range --project`` vs SimpleITK series read +
  ConnectedThreshold from the same seed + NIfTI write;
* info: ``ctui info BIG`` vs a pydicom header scan (``stop_before_pixels``, grouped and sorted);
* mesh --iso: ``ctui mesh BIG --iso L`` vs ``end_to_end.PEER`` (SimpleITK + VTK flying edges
  + STL + mass properties);
* MIP and DVR: ``ctui render BIG --mode mip|dvr --size 512x512`` vs SimpleITK read +
  ``vtkGPUVolumeRayCastMapper`` (maximum intensity / composite, ct-bone-like) + PNG;
* SEG export: ``ctui export KIDNEY.ctui --format dicom-seg`` vs highdicom ``Segmentation`` of the
  NIfTI mask over the pydicom-read source slices;
* load: ``open_input(BIG)`` in a fresh process vs SimpleITK's series reader.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the series and the kidney are made in this process with this tree's ctui
sys.path.insert(0, str(Path(__file__).resolve().parent))

from end_to_end import SERIES_AS_VTK  # noqa: E402

_VTK_WINDOW = r"""
def window(size):
    import vtk
    rw = vtk.vtkRenderWindow()
    rw.SetOffScreenRendering(1)
    rw.SetSize(size, size)
    ren = vtk.vtkRenderer()
    ren.SetBackground(0.15, 0.15, 0.15)
    rw.AddRenderer(ren)
    return rw, ren

def save(rw, out):
    import vtk
    rw.Render()
    w2i = vtk.vtkWindowToImageFilter()
    w2i.SetInput(rw)
    w2i.ReadFrontBufferOff()
    w2i.Update()
    png = vtk.vtkPNGWriter()
    png.SetFileName(out)
    png.SetInputConnection(w2i.GetOutputPort())
    png.Write()
"""

PEER_RENDER = _VTK_WINDOW + r"""
import sys, vtk
stl, out, size = sys.argv[1], sys.argv[2], int(sys.argv[3])
r = vtk.vtkSTLReader()
r.SetFileName(stl)
n = vtk.vtkPolyDataNormals()
n.SetInputConnection(r.GetOutputPort())
n.SplittingOff()
m = vtk.vtkPolyDataMapper()
m.SetInputConnection(n.GetOutputPort())
a = vtk.vtkActor()
a.SetMapper(m)
rw, ren = window(size)
ren.AddActor(a)
ren.ResetCamera()
save(rw, out)
print(n.GetOutput().GetNumberOfCells(), "triangles")
"""

PEER_VOLUME = _VTK_WINDOW + r"""
import sys, vtk
import SimpleITK as sitk
from vtk.util import numpy_support
series, mode, out, size = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
""" + SERIES_AS_VTK + r"""vimg.GetPointData().SetScalars(numpy_support.numpy_to_vtk(arr.ravel(), deep=False))
mapper = vtk.vtkGPUVolumeRayCastMapper()
mapper.SetInputData(vimg)
ctf = vtk.vtkColorTransferFunction()
otf = vtk.vtkPiecewiseFunction()
if mode == "mip":
    mapper.SetBlendModeToMaximumIntensity()
    ctf.AddRGBPoint(-1000, 0, 0, 0); ctf.AddRGBPoint(1000, 1, 1, 1)
    otf.AddPoint(-1000, 1.0); otf.AddPoint(3000, 1.0)
else:
    ctf.AddRGBPoint(150, 0.9, 0.6, 0.4); ctf.AddRGBPoint(700, 1.0, 1.0, 0.95)
    otf.AddPoint(150, 0.0); otf.AddPoint(300, 0.2); otf.AddPoint(1000, 0.8)
prop = vtk.vtkVolumeProperty()
prop.SetColor(ctf)
prop.SetScalarOpacity(otf)
prop.SetInterpolationTypeToLinear()
if mode != "mip":
    prop.ShadeOn()
v = vtk.vtkVolume()
v.SetMapper(mapper)
v.SetProperty(prop)
rw, ren = window(size)
ren.AddVolume(v)
ren.ResetCamera()
save(rw, out)
print(arr.shape)
"""

PEER_MEASURE = r"""
import sys
import numpy as np
import SimpleITK as sitk
from skimage import measure
import vtk
from vtk.util import numpy_support as ns
img = sitk.ReadImage(sys.argv[1])
mask = sitk.GetArrayViewFromImage(img) > 0
sp = img.GetSpacing()[::-1]
v, f, _, _ = measure.marching_cubes(np.pad(mask, 1).astype(np.float32), 0.5, spacing=sp)
pts = vtk.vtkPoints()
pts.SetData(ns.numpy_to_vtk(np.ascontiguousarray(v, np.float32), deep=True))
cells = vtk.vtkCellArray()
cells.SetData(ns.numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(f) + 1, 3, dtype=np.int64), deep=True),
              ns.numpy_to_vtkIdTypeArray(f.astype(np.int64).ravel(), deep=True))
pd = vtk.vtkPolyData()
pd.SetPoints(pts)
pd.SetPolys(cells)
mp = vtk.vtkMassProperties()
mp.SetInputData(pd)
mp.Update()
print(f"voxels {mask.sum() * np.prod(sp) / 1000:.2f} ml, mesh {mp.GetVolume() / 1000:.2f} ml, "
      f"area {mp.GetSurfaceArea():.0f} mm2")
"""

PEER_SEGMENT = r"""
import sys
import SimpleITK as sitk
series, seed, lo, hi, out = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
reader = sitk.ImageSeriesReader()
reader.SetFileNames(reader.GetGDCMSeriesFileNames(series))
img = reader.Execute()
x, y, z = (int(v) for v in seed.split(","))
seg = sitk.ConnectedThreshold(img, seedList=[(x, y, z)], lower=lo, upper=hi, replaceValue=1)
seg = sitk.BinaryMorphologicalClosing(seg, [1, 1, 1])
sitk.WriteImage(seg, out)
print(int(sitk.GetArrayViewFromImage(seg).sum()), "voxels")
"""

PEER_INFO = r"""
import sys, os
import pydicom
folder = sys.argv[1]
groups = {}
for name in os.listdir(folder):
    p = os.path.join(folder, name)
    try:
        ds = pydicom.dcmread(p, stop_before_pixels=True)
    except Exception:
        continue
    groups.setdefault(ds.SeriesInstanceUID, []).append(ds)
for uid, dss in groups.items():
    dss.sort(key=lambda d: float(d.ImagePositionPatient[2]))
    d = dss[0]
    print(len(dss), d.Rows, d.Columns, d.PixelSpacing, d.get("SliceThickness"), d.Modality)
"""

PEER_SEG = r"""
import sys, os
import numpy as np
import pydicom
import SimpleITK as sitk
import highdicom as hd
from pydicom.sr.codedict import codes
series, mask_path, out = sys.argv[1], sys.argv[2], sys.argv[3]
dss = [pydicom.dcmread(os.path.join(series, n)) for n in os.listdir(series) if not n.startswith(".")]
dss.sort(key=lambda d: float(d.ImagePositionPatient[2]))
for d in dss:  # type 2 attributes highdicom copies (ctui's writer leaves out what it does not know)
    for kw in ("PatientName", "PatientID", "PatientBirthDate", "PatientSex", "StudyDate", "StudyTime",
               "ReferringPhysicianName", "AccessionNumber", "StudyID"):
        if kw not in d:
            setattr(d, kw, "")
mask = sitk.GetArrayFromImage(sitk.ReadImage(mask_path)) > 0
desc = hd.seg.SegmentDescription(
    segment_number=1, segment_label="kidney", segmented_property_category=codes.SCT.Organ,
    segmented_property_type=codes.SCT.Kidney, algorithm_type=hd.seg.SegmentAlgorithmTypeValues.MANUAL)
seg = hd.seg.Segmentation(
    source_images=dss, pixel_array=mask, segmentation_type=hd.seg.SegmentationTypeValues.BINARY,
    segment_descriptions=[desc], series_instance_uid=hd.UID(), series_number=99,
    sop_instance_uid=hd.UID(), instance_number=1, manufacturer="peer", manufacturer_model_name="peer",
    software_versions="1", device_serial_number="1")
seg.save_as(out)
print(mask.sum(), "voxels")
"""

PEER_LOAD = r"""
import sys
import SimpleITK as sitk
reader = sitk.ImageSeriesReader()
reader.SetFileNames(reader.GetGDCMSeriesFileNames(sys.argv[1]))
img = reader.Execute()
print(sitk.GetArrayViewFromImage(img).shape)
"""

CTUI_LOAD = ("import sys; from ctui.engine.actions.opened import open_input; "
             "print(open_input(sys.argv[1]).volume.shape)")


def _run(cmd: list[str], env: dict) -> tuple[float, float, str]:
    """(wall s, CPU s of the process and its children, last stdout line) of one fresh process."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=err, cwd=ROOT)
        _, status, usage = os.wait4(proc.pid, 0)
        dt = time.perf_counter() - t
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{stderr[-2000:]}")
    lines = stdout.strip().splitlines()
    return dt, usage.ru_utime + usage.ru_stime, lines[-1] if lines else ""


def _setup(tmp: Path, args, make_series, make_kidney, peer_mesh: str, base: dict) -> tuple[list, dict]:
    """The inputs (big series, its STL, the kidney series, project and NIfTI mask) and the rows:
    (name, ctui argv, peer argv)."""
    py = sys.executable
    ctui = [py, "-m", "ctui.cli"]
    shape = tuple(int(v) for v in args.shape.split(","))
    series = make_series(shape)
    kidney, seed = make_kidney()
    from e2e_suite import KIDNEY_RANGE

    lo, hi = KIDNEY_RANGE.split(":")
    stl, proj, mask = tmp / "big.stl", tmp / "kidney.ctui", tmp / "kidney.nii.gz"
    subprocess.run(ctui + ["mesh", str(series), "--iso", str(args.level), "--out", str(stl)], env=base, check=True,
                   cwd=ROOT, capture_output=True)
    subprocess.run(ctui + ["segment", str(kidney), "--seed", seed, f"--range={KIDNEY_RANGE}", "--project",
                           str(proj)], env=base, check=True, cwd=ROOT, capture_output=True)
    subprocess.run(ctui + ["export", str(proj), "--format", "nifti", "--out", str(mask)], env=base, check=True,
                   cwd=ROOT, capture_output=True)
    scripts = {}
    for name, src in (("render", PEER_RENDER), ("volume", PEER_VOLUME), ("measure", PEER_MEASURE),
                      ("segment", PEER_SEGMENT), ("info", PEER_INFO), ("mesh", peer_mesh), ("seg", PEER_SEG),
                      ("load", PEER_LOAD)):
        scripts[name] = tmp / f"peer_{name}.py"
        scripts[name].write_text(src)
    o = tmp / "out"
    o.mkdir()
    big = f"{shape[0]}x{shape[1]}x{shape[2]}"
    rows = [
        ("render STL of the big series 1024x1024", ctui + ["render", str(stl), "--size", "1024x1024", "--out",
                                                           str(o / "r.png")],
         [py, str(scripts["render"]), str(stl), str(o / "pr.png"), "1024"]),
        ("measure kidney", ctui + ["measure", str(proj)], [py, str(scripts["measure"]), str(mask)]),
        ("segment kidney", ctui + ["segment", str(kidney), "--seed", seed, f"--range={KIDNEY_RANGE}", "--project",
                                   str(o / "k.ctui")],
         [py, str(scripts["segment"]), str(kidney), seed, lo, hi, str(o / "pk.nii.gz")]),
        (f"info {big}", ctui + ["info", str(series)], [py, str(scripts["info"]), str(series)]),
        (f"mesh --iso {args.level:g} {big}", ctui + ["mesh", str(series), "--iso", str(args.level), "--out",
                                                    str(o / "m.stl")],
         [py, str(scripts["mesh"]), str(series), str(args.level), str(o / "pm.stl")]),
        (f"render --mode mip {big} 512x512", ctui + ["render", str(series), "--mode", "mip", "--size", "512x512",
                                                     "--out", str(o / "mip.png")],
         [py, str(scripts["volume"]), str(series), "mip", str(o / "pmip.png"), "512"]),
        (f"render --mode dvr {big} 512x512", ctui + ["render", str(series), "--mode", "dvr", "--size", "512x512",
                                                     "--out", str(o / "dvr.png")],
         [py, str(scripts["volume"]), str(series), "dvr", str(o / "pdvr.png"), "512"]),
        ("export --format dicom-seg kidney", ctui + ["export", str(proj), "--format", "dicom-seg", "--out",
                                                     str(o / "k.dcm")],
         [py, str(scripts["seg"]), str(kidney), str(mask), str(o / "pk.dcm")]),
        (f"load DICOM {big}", [py, "-c", CTUI_LOAD, str(series)], [py, str(scripts["load"]), str(series)]),
    ]
    return rows, {"series": series}


def run_peers(args, *, make_series, make_kidney, peer_mesh: str) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="ctui-e2e-peers-"))
    cold_dir = tmp / "numba-cold"
    base = dict(os.environ, CTUI_NO_PROGRESS="1", CTUI_NO_BACKGROUND_COMPILE="1", PYTHONPATH=str(ROOT))
    for k in ("CTUI_KERNELS", "NUMBA_CACHE_DIR", "PYTHONDONTWRITEBYTECODE"):
        base.pop(k, None)
    cold = dict(base, NUMBA_CACHE_DIR=str(cold_dir))
    subprocess.run([sys.executable, "-m", "compileall", "-q", "ctui"], env=base, check=True, cwd=ROOT)
    subprocess.run([sys.executable, "-m", "ctui.engine.mesh.warm"], env=base, check=True, cwd=ROOT)
    rows, _ = _setup(tmp, args, make_series, make_kidney, peer_mesh, base)
    only = set(args.only.split(",")) if args.only else None
    print(f"{'command (fresh process, median of ' + str(args.repeat) + ')':44s} {'warm s':>7s} {'cold s':>7s} "
          f"{'peer s':>7s} {'warm/peer':>9s} {'cold/peer':>9s} {'cpu w/p':>8s}", flush=True)
    worst = []
    for name, cmd, peer in rows:
        if only and not any(o in name for o in only):
            continue
        w, c, p = [], [], []
        for _ in range(args.repeat):  # alternating: ctui warm, peer, ctui cold
            w.append(_run(cmd, base))
            p.append(_run(peer, base))
            shutil.rmtree(cold_dir, ignore_errors=True)
            cold_dir.mkdir()
            c.append(_run(cmd, cold))
        mw, mc, mp = (statistics.median(r[0] for r in x) for x in (w, c, p))
        cw, cp = (statistics.median(r[1] for r in x) for x in (w, p))
        worst.append((max(mw / mp, mc / mp / 1.5), name))
        print(f"{name:44s} {mw:7.2f} {mc:7.2f} {mp:7.2f} {mw / mp:9.2f} {mc / mp:9.2f} {cw / cp:8.2f}", flush=True)
        if args.verbose:
            print(f"    ctui: {w[-1][2][:100]}\n    peer: {p[-1][2][:100]}")
    print("goal: warm/peer <= 1.0, cold/peer <= 1.5; worst first: "
          + ", ".join(f"{n} ({r:.2f})" for r, n in sorted(worst, reverse=True)[:4]))
    shutil.rmtree(tmp, ignore_errors=True)
