"""Synthetic CT phantom with known truths: the bundled sample series and test base.

The phantom is defined analytically in patient mm (DICOM LPS: +x = patient left,
+y = posterior, +z = superior) and rasterised with partial-volume edges, so that
thresholding at the midpoint between an object's HU and its surroundings reproduces
its analytic volume closely.

Objects (all inside the body, separated from each other by soft tissue):

* ``body``: elliptical cylinder of soft tissue (40 HU) in air (-1000 HU) along z;
* ``kidney_left`` / ``kidney_right``: contrast-enhanced ellipsoids (190 / 220 HU),
  about 140 ml each;
* ``spine``: bone cylinder (700 HU) along z, posterior, through all slices;
* ``tube``: a metal rod (1500 HU) along z whose circular cross-section steps
  (radii 12, 9, 6 mm), like a stepped rod in a QA phantom;
* a slow drift: a few consecutive slices have their whole content shifted by a few
  pixels (the patient moved); volumes are unchanged (integer-pixel shifts).

Default grid: 80 slices of 128 x 128, pixel 2 mm, slices 2.5 mm (anisotropic). Values
are stored as the DICOM files store them (uint16, intercept -1024, slope 1) so the
volume returned by :func:`make_phantom` equals what loading the written series gives.

Public API
----------
make_phantom(**opts) -> (Volume, truth dict)
write_demo(outdir, **opts) -> Path      DICOM series (shuffled file names) + truth.json
SAMPLE_DIR                              bundled copy: <repo>/sample_data/phantom
sample_path() -> Path                   SAMPLE_DIR, regenerated into a cache if absent
load_truth(path=None) -> dict           truth.json of the bundled (or given) series
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.atomic import atomic_write, write_text
from ctui.engine.core.volume import Volume

SAMPLE_DIR = Path(__file__).resolve().parents[3] / "sample_data" / "phantom"
TRUTH_NAME = "truth.json"
PATIENT_NAME = "PHANTOM^SYNTHETIC"  # obviously synthetic; never a real identifier

AIR_HU = -1000.0
BODY_HU = 40.0

# Geometry in patient mm. Volumes are analytic.
BODY = {"name": "body", "center_xy": (0.0, 0.0), "semi_axes_xy": (115.0, 85.0), "hu": BODY_HU}
KIDNEYS = [
    {"name": "kidney_left", "center": (60.0, 35.0, 5.0), "semi_axes": (27.0, 23.0, 55.0), "hu": 190.0},
    {"name": "kidney_right", "center": (-60.0, 35.0, -5.0), "semi_axes": (25.0, 22.0, 58.0), "hu": 220.0},
]
SPINE = {"name": "spine", "center_xy": (0.0, 55.0), "radius": 16.0, "hu": 700.0}
TUBE = {
    "name": "tube",
    "center_xy": (0.0, -45.0),
    "hu": 1500.0,
    # (z where the step starts, radius); the tube ends at TUBE_END_Z
    "steps": [(-80.0, 12.0), (-30.0, 9.0), (25.0, 6.0)],
    "end_z": 80.0,
}
# drifted slices: index -> (dy, dx) in pixels (whole-slice content shift)
DRIFT = {48: (1, 2), 49: (2, 3), 50: (2, 4), 51: (1, 2)}


def _coverage_1d(lo: float, hi: float, c0: float, c1: float) -> float:
    """Fraction of [c0, c1] covered by [lo, hi]."""
    return max(0.0, min(hi, c1) - max(lo, c0)) / (c1 - c0)


def _grid(n: int, d: float) -> np.ndarray:
    """Voxel centres in mm of an axis of n voxels of size d, centred on 0."""
    return (np.arange(n) - (n - 1) / 2.0) * d


def _disk_cover(xc: np.ndarray, yc: np.ndarray, dx: float, dy: float, inside, ss: int) -> np.ndarray:
    """In-plane coverage (ny, nx) of a 2D shape given by ``inside(x, y) -> bool``.

    Supersampled ss x ss per pixel, only where the pixel straddles the boundary.
    """
    off = (np.arange(ss) + 0.5) / ss - 0.5
    X, Y = np.meshgrid(xc, yc)
    centre = inside(X, Y).astype(np.float64)
    # pixels whose corners disagree with the centre straddle the boundary; grow that
    # set by one pixel so slivers clipped between two corners are supersampled too
    corners = [inside(X + sx * dx / 2, Y + sy * dy / 2) for sx in (-1, 1) for sy in (-1, 1)]
    edge = np.zeros(centre.shape, dtype=bool)
    for c in corners:
        edge |= c != centre.astype(bool)
    mixed = edge.copy()
    mixed[1:] |= edge[:-1]
    mixed[:-1] |= edge[1:]
    mixed[:, 1:] |= edge[:, :-1]
    mixed[:, :-1] |= edge[:, 1:]
    jj, ii = np.nonzero(mixed)
    if jj.size:
        sx = X[jj, ii][:, None, None] + off[None, None, :] * dx
        sy = Y[jj, ii][:, None, None] + off[None, :, None] * dy
        sub = inside(np.broadcast_to(sx, (jj.size, ss, ss)), np.broadcast_to(sy, (jj.size, ss, ss)))
        centre[jj, ii] = sub.reshape(jj.size, -1).mean(axis=1)
    return centre


def make_phantom(
    *,
    shape: tuple[int, int, int] = (80, 128, 128),
    spacing: tuple[float, float, float] = (2.5, 2.0, 2.0),
    noise_sd: float = 8.0,
    seed: int = 0,
    drift: bool = True,
    supersample: int = 8,
) -> tuple[Volume, dict[str, Any]]:
    """Build the synthetic CT phantom.

    Parameters
    ----------
    shape : (nz, ny, nx)
        Grid size; the grid is centred on the patient origin. It must cover the body
        (230 x 170 mm in-plane, 200 mm along z for the full kidneys/tube).
    spacing : (dz, dy, dx) in mm.
    noise_sd : float
        Gaussian noise sigma in HU (fixed ``seed``).
    drift : bool
        Shift the content of slices 48..51 by 1-2 px in y and 2-4 px in x.
    supersample : int
        Sub-samples per axis for partial-volume edges.

    Returns
    -------
    volume : Volume
        data int16 HU (z, y, x), quantised exactly as the DICOM files store it.
    truth : dict
        JSON-ready description of each object (see ``truth.json``).
    """
    nz, ny, nx = (int(s) for s in shape)
    dz, dy, dx = (float(s) for s in spacing)
    if nx * dx < 2 * (BODY["semi_axes_xy"][0] + 10) or ny * dy < 2 * (BODY["semi_axes_xy"][1] + 10):
        raise ValueError("phantom grid too small in-plane for the body (needs >= 250 x 190 mm)")
    ss = max(1, int(supersample))
    xc, yc, zc = _grid(nx, dx), _grid(ny, dy), _grid(nz, dz)
    vol = _body_spine_tube(xc, yc, zc, (dz, dy, dx), ss)
    _add_kidneys(vol, xc, yc, zc, (dz, dy, dx), ss)
    drift_map = DRIFT if drift else {}
    _shift_slices(vol, drift_map)

    rng = np.random.default_rng(seed)
    if noise_sd > 0:
        vol += rng.normal(0.0, noise_sd, size=vol.shape)
    stored = np.clip(np.rint(vol + 1024.0), 0, 65535).astype(np.uint16)
    data = (stored.astype(np.int32) - 1024).astype(np.int16)

    origin = (float(xc[0]), float(yc[0]), float(zc[0]))
    volume = Volume(
        data=data,
        spacing=(dz, dy, dx),
        origin=origin,
        direction=np.eye(3),
        modality="CT",
        window=(40.0, 400.0),
        source="ctui synthetic phantom",
        slice_positions=zc.copy(),
        meta={"synthetic": True},
    )
    truth = _truth(volume, xc, yc, zc, drift_map, noise_sd, seed)
    return volume, truth


def _body_spine_tube(xc, yc, zc, spacing, ss: int) -> np.ndarray:
    """HU (z, y, x) float64: air, the body, the spine and the stepped tube (partial-volume edges)."""
    dz, dy, dx = spacing
    nz, ny, nx = len(zc), len(yc), len(xc)
    # start with air, add body (z-invariant elliptical cylinder)
    bx, by = BODY["center_xy"]
    ax, ay = BODY["semi_axes_xy"]
    body2d = _disk_cover(xc, yc, dx, dy, lambda X, Y: ((X - bx) / ax) ** 2 + ((Y - by) / ay) ** 2 <= 1.0, ss)
    vol = np.empty((nz, ny, nx), np.float64)
    vol[:] = AIR_HU + body2d[None] * (BODY_HU - AIR_HU)

    # spine: cylinder along z through all slices
    sx0, sy0 = SPINE["center_xy"]
    r = SPINE["radius"]
    spine2d = _disk_cover(xc, yc, dx, dy, lambda X, Y: (X - sx0) ** 2 + (Y - sy0) ** 2 <= r * r, ss)
    vol += spine2d[None] * (SPINE["hu"] - BODY_HU)

    # tube: radius steps along z; exact z-coverage per slice times in-plane coverage
    tx0, ty0 = TUBE["center_xy"]
    steps = TUBE["steps"]
    bounds = [s[0] for s in steps] + [TUBE["end_z"]]
    for si, (z0, rad) in enumerate(steps):
        z1 = bounds[si + 1]
        fz = np.array([_coverage_1d(z0, z1, z - dz / 2, z + dz / 2) for z in zc])
        if not fz.any():
            continue
        cov = _disk_cover(xc, yc, dx, dy, lambda X, Y, rad=rad: (X - tx0) ** 2 + (Y - ty0) ** 2 <= rad * rad, ss)
        vol += fz[:, None, None] * cov[None] * (TUBE["hu"] - BODY_HU)
    return vol


def _add_kidneys(vol: np.ndarray, xc, yc, zc, spacing, ss: int) -> None:
    """Add the two kidneys (ellipsoids) to ``vol`` in place."""
    dz, dy, dx = spacing
    # kidneys: ellipsoids, supersampled in their bounding boxes (at most 4^3: the
    # 6-D broadcast grows as ss^3)
    ss3 = min(ss, 4)
    off = (np.arange(ss3) + 0.5) / ss3 - 0.5
    for k in KIDNEYS:
        (cx, cy, cz), (a, b, c) = k["center"], k["semi_axes"]
        iz = np.nonzero(np.abs(zc - cz) <= c + dz)[0]
        iy = np.nonzero(np.abs(yc - cy) <= b + dy)[0]
        ix = np.nonzero(np.abs(xc - cx) <= a + dx)[0]
        Z = (zc[iz][:, None] + off[None, :] * dz - cz) / c  # (nz', ss)
        Y = (yc[iy][:, None] + off[None, :] * dy - cy) / b
        X = (xc[ix][:, None] + off[None, :] * dx - cx) / a
        q = (
            Z[:, None, None, :, None, None] ** 2
            + Y[None, :, None, None, :, None] ** 2
            + X[None, None, :, None, None, :] ** 2
        )
        cov = (q <= 1.0).mean(axis=(3, 4, 5))
        vol[np.ix_(iz, iy, ix)] += cov * (k["hu"] - BODY_HU)


def _shift_slices(vol: np.ndarray, drift_map: dict) -> None:
    """Shift whole slices in place (content as if the patient moved), air fills in."""
    nz, ny, nx = vol.shape
    for z, (sy, sx) in drift_map.items():
        if 0 <= z < nz:
            sl = np.full((ny, nx), AIR_HU)
            src = vol[z]
            sl[max(sy, 0) : ny + min(sy, 0), max(sx, 0) : nx + min(sx, 0)] = src[
                max(-sy, 0) : ny + min(-sy, 0), max(-sx, 0) : nx + min(-sx, 0)
            ]
            vol[z] = sl


def _index(volume: Volume, xyz: tuple[float, float, float]) -> list[int]:
    return [int(round(v)) for v in volume.mm_to_index(np.asarray(xyz, float))]


def _kidneys_truth(volume: Volume, zmid: float) -> list[dict[str, Any]]:
    pi = float(np.pi)
    objects: list[dict[str, Any]] = []
    for label, k in enumerate(KIDNEYS, start=2):
        a, b, c = k["semi_axes"]
        cx, cy, cz = k["center"]
        objects.append(
            {
                "name": k["name"],
                "label": label,
                "hu": k["hu"],
                "volume_ml": 4.0 / 3.0 * pi * a * b * c / 1000.0,
                "shape": "ellipsoid",
                "center_xyz_mm": [cx, cy, cz],
                "semi_axes_xyz_mm": [a, b, c],
                "cross_section_mm2": pi * a * b,
                "cross_section_note": "largest axial cross-section (at the centre z)",
                "hu_range": [(k["hu"] + BODY_HU) / 2, (k["hu"] + SPINE["hu"]) / 2],
                "seed_zyx": _index(volume, (cx, cy, zmid)),
            }
        )
    return objects


def _tube_truth(volume: Volume, zmid: float) -> dict[str, Any]:
    pi = float(np.pi)
    bounds = [s[0] for s in TUBE["steps"]] + [TUBE["end_z"]]
    start = TUBE["steps"][0][0]
    steps = []
    tube_ml = 0.0
    for i, (z0, rad) in enumerate(TUBE["steps"]):
        length = bounds[i + 1] - z0
        tube_ml += pi * rad * rad * length / 1000.0
        steps.append(
            {
                "start_mm": z0 - start,
                "start_z_mm": z0,
                "length_mm": length,
                "radius_mm": rad,
                "radius_px": rad / volume.spacing[2],
                "cross_section_mm2": pi * rad * rad,
            }
        )
    return (
        {
            "name": "tube",
            "label": 5,
            "hu": TUBE["hu"],
            "volume_ml": tube_ml,
            "shape": "solid rod along z with stepped circular cross-section",
            "axis": {
                "point_xyz_mm": [*TUBE["center_xy"], start],
                "direction_xyz": [0.0, 0.0, 1.0],
                "length_mm": TUBE["end_z"] - start,
            },
            "steps": steps,
            "hu_range": [(TUBE["hu"] + BODY_HU) / 2, 4000.0],
            "seed_zyx": _index(volume, (*TUBE["center_xy"], zmid)),
        }
    )


def _truth(volume, xc, yc, zc, drift_map, noise_sd, seed) -> dict[str, Any]:
    pi = float(np.pi)
    nz = volume.shape[0]
    z_lo, z_hi = float(zc[0] - volume.spacing[0] / 2), float(zc[-1] + volume.spacing[0] / 2)
    mid = nz // 2  # seed slice, away from the drifted ones
    zmid = float(zc[mid])
    objects: list[dict[str, Any]] = []

    ax, ay = BODY["semi_axes_xy"]
    objects.append(
        {
            "name": "body",
            "label": 1,
            "hu": BODY_HU,
            "volume_ml": pi * ax * ay * (z_hi - z_lo) / 1000.0,
            "volume_note": "whole elliptical cylinder including everything inside it, over the grid's z extent",
            "shape": "elliptical cylinder along z",
            "center_xy_mm": list(BODY["center_xy"]),
            "semi_axes_xy_mm": [ax, ay],
            "cross_section_mm2": pi * ax * ay,
            "hu_range": [(AIR_HU + BODY_HU) / 2, 4000.0],
            "seed_zyx": _index(volume, (-90.0, 0.0, zmid)),
        }
    )
    objects += _kidneys_truth(volume, zmid)
    r = SPINE["radius"]
    objects.append(
        {
            "name": "spine",
            "label": 4,
            "hu": SPINE["hu"],
            "volume_ml": pi * r * r * (z_hi - z_lo) / 1000.0,
            "shape": "cylinder along z through all slices",
            "center_xy_mm": list(SPINE["center_xy"]),
            "radius_mm": r,
            "cross_section_mm2": pi * r * r,
            "hu_range": [(SPINE["hu"] + BODY_HU) / 2, (SPINE["hu"] + TUBE["hu"]) / 2],
            "seed_zyx": _index(volume, (*SPINE["center_xy"], zmid)),
        }
    )
    objects.append(_tube_truth(volume, zmid))
    return {
        "description": "ctui synthetic CT phantom (not a patient)",
        "units": {"volume": "ml", "length": "mm", "values": "HU"},
        "coordinates": "DICOM LPS patient mm; indices (z, y, x); slice 0 lowest z",
        "shape_zyx": list(volume.shape),
        "spacing_zyx_mm": list(volume.spacing),
        "origin_xyz_mm": list(volume.origin),
        "noise_sd_hu": noise_sd,
        "seed": seed,
        "background_hu": AIR_HU,
        "objects": objects,
        "drift": {
            "slices": sorted(drift_map),
            "shifts_px_yx": [list(drift_map[z]) for z in sorted(drift_map)],
            "shifts_mm_yx": [
                [drift_map[z][0] * volume.spacing[1], drift_map[z][1] * volume.spacing[2]] for z in sorted(drift_map)
            ],
            "note": "whole-slice content shifted by these pixels (positive = towards higher y / x index); "
            "object volumes are unchanged",
        },
    }


def _uid(*parts: object) -> str:
    from pydicom.uid import PYDICOM_ROOT_UID, generate_uid

    # deterministic (hash of the sources) so regenerated files are byte-identical;
    # prefix=None would ignore entropy_srcs and draw a random UUID
    return generate_uid(prefix=PYDICOM_ROOT_UID, entropy_srcs=["ctui-phantom", *map(str, parts)])


def write_series(
    outdir: str | os.PathLike,
    volume: Volume,
    *,
    seed: int = 0,
    description: str = "ctui demo CT",
    bits_stored: int = 16,
) -> list[Path]:
    """Write ``volume`` (CT, HU) as a DICOM CT Image Storage series with shuffled file names.

    Stored as uint16 with RescaleIntercept -1024; positions from the volume's geometry.
    Deterministic: the same volume and seed give byte-identical files. ``bits_stored``
    12 gives the common CT layout (values must then fit 0..4095 stored). Returns the written paths
    (in slice order).
    """
    import pydicom
    from pydicom.dataset import FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    nz, ny, nx = volume.shape
    stored = np.clip(volume.data.astype(np.int32) + 1024, 0, 2**bits_stored - 1).astype(np.uint16)
    rng = np.random.default_rng(seed + 1)
    names = [f"IM{n:04d}.dcm" for n in rng.permutation(nz) + 1]
    study, series, frame = _uid("study", seed), _uid("series", seed, description), _uid("frame", seed)
    dz, dy, dx = volume.spacing
    row_dir = volume.direction[:, 0]
    col_dir = volume.direction[:, 1]
    paths = []
    for z in range(nz):
        ds = pydicom.Dataset()
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = _uid("instance", seed, description, z)
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID = study
        ds.SeriesInstanceUID = series
        ds.FrameOfReferenceUID = frame
        ds.PatientName = PATIENT_NAME
        ds.PatientID = "SYNTHETIC-0000"
        ds.PatientSex = "O"
        ds.StudyDate = "20000101"
        ds.StudyTime = "000000"
        ds.Modality = "CT"
        ds.Manufacturer = "ctui"
        ds.StudyDescription = "synthetic phantom"
        ds.SeriesDescription = description
        ds.SeriesNumber = 1
        ds.InstanceNumber = z + 1
        ds.PatientPosition = "HFS"
        ds.ImageType = ["DERIVED", "SECONDARY", "AXIAL"]
        pos = volume.index_to_mm((z, 0, 0))
        ds.ImagePositionPatient = [f"{v:.4f}".rstrip("0").rstrip(".") if v else "0" for v in pos]
        ds.ImageOrientationPatient = [float(v) for v in (*row_dir, *col_dir)]
        ds.SliceLocation = f"{pos[2]:.4f}".rstrip("0").rstrip(".") or "0"
        ds.SliceThickness = dz
        ds.PixelSpacing = [dy, dx]
        ds.KVP = 120
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.Rows, ds.Columns = ny, nx
        ds.BitsAllocated = 16
        ds.BitsStored = bits_stored
        ds.HighBit = bits_stored - 1
        ds.PixelRepresentation = 0
        ds.RescaleIntercept = -1024
        ds.RescaleSlope = 1
        ds.RescaleType = "HU"
        ds.WindowCenter = 40
        ds.WindowWidth = 400
        ds.PixelData = stored[z].tobytes()
        path = out / names[z]
        with atomic_write(path, "wb") as fh:
            pydicom.dcmwrite(fh, ds, enforce_file_format=True)
        paths.append(path)
    return paths


def write_demo(outdir: str | os.PathLike, **opts: Any) -> Path:
    """Write the phantom series (DICOM, shuffled names) and ``truth.json`` into ``outdir``.

    ``opts`` go to :func:`make_phantom`. Returns ``outdir`` as a Path.
    """
    volume, truth = make_phantom(**opts)
    out = Path(outdir)
    paths = write_series(out, volume, seed=int(opts.get("seed", 0)))
    truth["files"] = len(paths)
    write_text(out / TRUTH_NAME, json.dumps(truth, indent=1) + "\n")
    return out


def sample_path() -> Path:
    """The bundled phantom folder; regenerated into ``~/.cache/ctui/phantom`` if absent."""
    if (SAMPLE_DIR / TRUTH_NAME).is_file():
        return SAMPLE_DIR
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "ctui" / "phantom"
    if not (cache / TRUTH_NAME).is_file():
        write_demo(cache)
    return cache


def load_truth(path: str | os.PathLike | None = None) -> dict[str, Any]:
    """Read ``truth.json`` from ``path`` (a folder or the file) or the bundled sample."""
    p = Path(path) if path is not None else sample_path()
    if p.is_dir():
        p = p / TRUTH_NAME
    with open(p, encoding="utf-8") as fh:
        return json.load(fh)
