"""Test phantoms reproducing the real leak cases of issue 14 (not the bundled sample).

Each :func:`leak_case` is a small CT-like volume with anisotropic voxels as in an
abdominal CT (3 mm slices, 0.8 mm pixels): a kidney-like ellipsoid (200 HU, noise sd
10 HU, soft tissue 40 HU around) and a neighbour of the same HU joined to it:

* ``"neck"``: another organ (a second ellipsoid) touching the kidney through a neck
  3 pixels wide (2.4 mm) on 6 slices;
* ``"bowel"``: a winding bowel loop (a tube of 9 mm radius) running along the slices
  beside the kidney, joined by a 2-pixel partial-volume bridge on 12 slices;
* ``"slow"``: a neighbour whose section grows by 20% a slice over 30 slices, joined to
  the kidney by a 3-pixel neck on every one of them (a slow leak: the slice-to-slice
  area ratio never exceeds 1.2, so an area guard never fires).

The result is a :class:`LeakCase`: the volume, the kidney's truth mask, a seed in the
kidney (x, y, z), the HU range, and a background seed in the neighbour.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ctui.engine.core.volume import Volume

SPACING = (3.0, 0.8, 0.8)
KINDS = ("neck", "bowel", "slow")


@dataclass
class LeakCase:
    """A phantom: ``volume``, ``truth`` (bool (nz, ny, nx), the kidney), ``seed`` and
    ``background`` (x, y, z voxel indices), ``hu_range`` (low, high)."""

    kind: str
    volume: Volume
    truth: np.ndarray
    seed: tuple[int, int, int]
    background: tuple[int, int, int]
    hu_range: tuple[float, float] = (120.0, 300.0)

    @property
    def truth_ml(self) -> float:
        return float(self.truth.sum()) * float(np.prod(SPACING)) / 1000.0


def _ellipsoid(shape: tuple[int, int, int], centre_mm: tuple[float, float, float],
               semi_mm: tuple[float, float, float]) -> np.ndarray:
    """bool mask of an ellipsoid, centre and semi-axes (z, y, x) in mm, on the SPACING grid."""
    zz, yy, xx = (np.arange(n) * s for n, s in zip(shape, SPACING))
    d = (((zz[:, None, None] - centre_mm[0]) / semi_mm[0]) ** 2 + ((yy[None, :, None] - centre_mm[1]) / semi_mm[1]) ** 2
         + ((xx[None, None, :] - centre_mm[2]) / semi_mm[2]) ** 2)
    return d <= 1.0


def _bridge(mask: np.ndarray, zs: range, y: int, x0: int, x1: int, width: int) -> None:
    """A bar ``width`` px high (rows y..y+width-1), columns x0..x1, on slices ``zs``."""
    for z in zs:
        mask[z, y:y + width, x0:x1 + 1] = True


def leak_case(kind: str, *, seed: int = 0) -> LeakCase:
    """Build one phantom (see the module docstring). Shape (40, 150, 190), 3 x 0.8 x 0.8 mm."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}")
    shape = (40, 150, 190)
    nz, ny, nx = shape
    kidney = _ellipsoid(shape, (60.0, 60.0, 50.0), (54.0, 30.0, 22.0))  # columns 35..90, rows 37..112, slices 2..38
    other = np.zeros(shape, bool)
    yy, xx = np.mgrid[:ny, :nx]
    right = 91 + 5  # kidney's widest right edge is column ~90; the neighbour starts 6 px beyond
    if kind == "neck":
        other = _ellipsoid(shape, (66.0, 60.0, 104.0), (45.0, 32.0, 24.0))  # left edge x 80 mm = column 100
        _bridge(other, range(18, 24), 74, 88, 102, 3)
        bg = (130, 75, 22)
    elif kind == "bowel":
        for z in range(nz):
            cx = 112 + 6 * np.sin(z / 5.0)
            cy = 75 + 25 * np.cos(z / 7.0)
            other[z] = (xx - cx) ** 2 + (yy - cy) ** 2 <= (9.0 / 0.8) ** 2
        for z in range(14, 26):
            cy = int(round(75 + 25 * np.cos(z / 7.0)))
            other[z, cy:cy + 2, 60:int(112 + 6 * np.sin(z / 5.0))] = True
        bg = (int(round(112 + 6 * np.sin(4.0))), int(round(75 + 25 * np.cos(20 / 7.0))), 20)
    else:
        for k, z in enumerate(range(5, 35)):
            area = 20.0 * 1.2**k  # pixels: 20 -> 4200 over 30 slices, 20% a slice
            r = np.sqrt(area / np.pi)
            other[z] = (xx - (right + 4 + r)) ** 2 + (yy - 75) ** 2 <= r * r
            other[z, 74:77, 60:right + 6] = True  # 3-px neck to the kidney on every slice
        bg = (right + 40, 75, 30)
    other &= ~kidney
    rng = np.random.default_rng(seed)
    data = np.full(shape, 40.0, np.float32)
    data[kidney | other] = 200.0
    data += rng.normal(0.0, 10.0, shape).astype(np.float32)
    vol = Volume(np.round(data).astype(np.int16), spacing=SPACING, modality="CT")
    return LeakCase(kind=kind, volume=vol, truth=kidney, seed=(62, 75, 20), background=bg)


# Enhancement (HU added) of a portal-venous / nephrographic phase, by TotalSegmentator class: kidneys 160
# (190 HU, in the 120:400 users give), aorta 250, vena cava and portal vein 150, spleen 100, liver 60.
ENHANCEMENT = {2: 160.0, 3: 160.0, 52: 250.0, 63: 150.0, 64: 150.0, 1: 100.0, 5: 60.0}
VEIN_HU = 150.0
CORTEX_MM = 5.0  # corticomedullary phase: the kidney's outer shell this thick is cortex
CORTEX_HU, MEDULLA_HU = 190.0, 80.0  # added: cortex ~220 HU, medulla ~110 HU


def contrast_abdomen(volume: Volume, labels: np.ndarray, *, vein_mm: float = 10.0,
                     phase: str = "nephrographic") -> Volume:
    """A contrast-enhanced copy of an unenhanced abdominal CT with TotalSegmentator labels (same grid).

    Each labelled organ gets :data:`ENHANCEMENT` added; each kidney (labels 2, 3) gets a renal vein:
    the cheapest path through unlabelled soft tissue from the kidney's voxel nearest the vena cava
    (label 63) to it, ``vein_mm`` wide, enhanced by :data:`VEIN_HU` (the path a fill leaks along into
    the vena cava, the aorta and the spine on a real contrast CT). ``phase="corticomedullary"``: each
    kidney's outer ``CORTEX_MM`` is cortex (about 220 HU) and its inside medulla (about 110 HU), the
    arterial phase's contrast between them. The organs keep their real shapes, contacts and noise, and
    the labels stay their truth. ``volume.data`` (nz, ny, nx) HU; returns a Volume with int16 data on
    the same grid.
    """
    from scipy import ndimage
    from skimage.graph import route_through_array  # test data only: not on any command's path

    data = volume.data.astype(np.float32)
    sp = tuple(float(v) for v in volume.spacing)
    for lab, hu in ENHANCEMENT.items():
        organ = labels == lab
        if phase == "corticomedullary" and lab in (2, 3):
            cortex = organ & (ndimage.distance_transform_edt(organ, sampling=sp) <= CORTEX_MM)
            data[cortex] += CORTEX_HU
            data[organ & ~cortex] += MEDULLA_HU
        else:
            data[organ] += hu
    ivc = labels == 63
    soft = (labels == 0) & (volume.data > -50) & (volume.data < 100)
    cost = np.where(soft | ivc, 1.0, 50.0)
    dist, nearest = ndimage.distance_transform_edt(~ivc, sampling=sp, return_indices=True)
    veins = np.zeros(labels.shape, bool)
    for lab in (2, 3):
        kidney = labels == lab
        if not kidney.any() or not ivc.any():
            continue
        pts = np.argwhere(kidney)
        a = tuple(int(v) for v in pts[int(np.argmin(dist[kidney]))])
        b = tuple(int(nearest[i][a]) for i in range(3))
        path, _cost = route_through_array(cost, a, b, fully_connected=True, geometric=True)
        line = np.zeros(labels.shape, bool)
        line[tuple(np.array(path).T)] = True
        veins |= (ndimage.distance_transform_edt(~line, sampling=sp) <= vein_mm / 2.0) & (labels == 0)
    data[veins] += VEIN_HU
    return replace(volume, data=np.round(data).astype(np.int16))
