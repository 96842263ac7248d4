"""Label-map export and import: NIfTI (.nii, .nii.gz) and NRRD (.nrrd, .seg.nrrd); import only: GIPL
(.gipl, .gipl.gz: ITK-SNAP's segmentations).

Written with the maintained libraries (nibabel, pynrrd) so 3D Slicer, ITK-SNAP and
friends open the files aligned with the source series.

Geometry conventions
--------------------
ctui: labels are (z, y, x); ``Volume.affine`` maps (x, y, z) indices to LPS mm.

* NIfTI stores data in (x, y, z) order and its affine maps (i, j, k) to **RAS** mm;
  so the file's data is ``labels.transpose(2, 1, 0)`` and its affine is
  ``diag(-1, -1, 1, 1) @ volume.affine`` (x and y rows negated). Both qform and sform
  are set (code 1, scanner), units mm, intent "label".
* NRRD: data in (x, y, z) order (x fastest, as Slicer writes), ``space:
  left-posterior-superior``, ``space directions`` rows = index-axis vectors in LPS mm
  (``direction[:, i] * spacing_i``), ``space origin`` = ``volume.origin``.
* ``.seg.nrrd`` adds the ``Segment{i}_*`` and ``Segmentation_*`` key/value pairs that
  3D Slicer's segmentation storage node reads (ID, Name, Color, LabelValue, Layer,
  Extent, Tags...), so Slicer opens the file as a segmentation with one segment per
  object, each in ctui's object colour.

Reading validates the declared data size against the file size before decompressing
(deflate cannot expand more than ~1032:1), so a corrupted header or a "zip bomb"
cannot make ctui allocate more than the file can justify.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ctui.engine.core.atomic import atomic_path, regular_source
from ctui.engine.core.colors import object_color_float
from ctui.engine.core.errors import CtuiError, FormatError
from ctui.engine.core.limits import check_allocation
from ctui.engine.core.volume import Volume
from ctui.engine.io.series.nrrd_data import inflate_bounded
from ctui.engine.io.suffixes import GIPL_SUFFIXES

#: Largest expansion deflate (gzip/zlib) can achieve; bounds decompressed sizes.
DEFLATE_MAX_RATIO = 1032
#: Largest label volume accepted on reading (voxels).
MAX_VOXELS = 2**31 - 1
LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])


def present_ids(labels: np.ndarray) -> list[int]:
    """The label values other than 0 in a (z, y, x) uint8 label volume, ascending. Counted 4 M
    voxels at a time: ``np.bincount`` copies its input to int64 first (8 bytes a voxel: 4x the
    series for a whole volume, the peak of ``measure`` and ``export``)."""
    flat = np.asarray(labels, np.uint8).reshape(-1)
    seen = np.zeros(256, bool)
    for i in range(0, flat.size, 1 << 22):
        seen |= np.bincount(flat[i:i + (1 << 22)], minlength=256) > 0
    return [int(v) for v in np.flatnonzero(seen[1:]) + 1]


def _kind(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".seg.nrrd"):
        return "seg.nrrd"
    if name.endswith(".nii.gz"):
        return "nii.gz"
    if name.endswith(".nii"):
        return "nii"
    if name.endswith(".nrrd"):
        return "nrrd"
    if name.endswith(GIPL_SUFFIXES):
        return "gipl"
    raise FormatError(f"{path}: unknown label-map format (use .nii, .nii.gz, .nrrd, .seg.nrrd or .gipl)")


def _check_labels(path, labels: np.ndarray, volume: Volume) -> np.ndarray:
    labels = np.asarray(labels)
    if labels.ndim != 3:
        raise FormatError(f"{path}: labels must be 3D (z, y, x), got shape {labels.shape}")
    if tuple(labels.shape) != tuple(volume.shape):
        raise FormatError(f"{path}: labels shape {labels.shape} differs from the volume's {volume.shape}")
    if labels.dtype != np.uint8:
        if labels.size and (labels.min() < 0 or labels.max() > 255):
            raise FormatError(f"{path}: label values outside 0..255")
        labels = labels.astype(np.uint8)
    return labels


# --------------------------------------------------------------------------- saving
def save_labels(path: str | os.PathLike, labels: np.ndarray, volume: Volume, *, names: dict[int, str] | None = None) -> Path:
    """Save a label volume with the source volume's geometry.

    Parameters
    ----------
    path : path
        Target; format from the extension: ``.nii``, ``.nii.gz``, ``.nrrd`` or
        ``.seg.nrrd``. Written atomically.
    labels : ndarray (z, y, x) uint8
        0 background, 1..10 objects; same shape as ``volume.data``.
    volume : Volume
        Source of the geometry (spacing, origin, direction).
    names : dict {object id: name}, optional
        Segment names for ``.seg.nrrd`` (default "Object N").

    Returns
    -------
    Path of the written file.
    """
    p = Path(path)
    kind = _kind(p)
    labels = _check_labels(p, labels, volume)
    if kind in ("nii", "nii.gz"):
        _save_nifti(p, labels, volume)
    else:
        _save_nrrd(p, labels, volume, seg=(kind == "seg.nrrd"), names=names or {})
    return p


def nifti_affine(volume: Volume) -> np.ndarray:
    """4x4 NIfTI (RAS) affine for ``volume``: (i, j, k) = (x, y, z) indices -> RAS mm."""
    return LPS_TO_RAS @ volume.affine


def _save_nifti(p: Path, labels: np.ndarray, volume: Volume) -> None:
    import nibabel as nib

    aff = nifti_affine(volume)
    img = nib.Nifti1Image(labels.transpose(2, 1, 0), aff)  # a view: nibabel writes it in NIfTI (Fortran) order, no copy
    hdr = img.header
    hdr.set_data_dtype(np.uint8)
    hdr.set_xyzt_units("mm")
    hdr.set_intent("label")
    hdr["descrip"] = b"ctui label map"
    img.set_qform(aff, code=1)
    img.set_sform(aff, code=1)
    with atomic_path(p) as tmp:
        nib.save(img, str(tmp))


def nrrd_geometry(volume: Volume) -> dict:
    """NRRD header fields (LPS) for ``volume``'s geometry, data in (x, y, z) order."""
    dirs = volume.geometry.affine[:3, :3]  # columns = index axes (x, y, z), mm per voxel
    return {
        "space": "left-posterior-superior",
        "space directions": dirs.T.copy(),  # rows = index axes
        "space origin": np.asarray(volume.origin, dtype=np.float64),
        "kinds": ["domain", "domain", "domain"],
    }


def _segment_fields(labels: np.ndarray, names: dict[int, str]) -> dict[str, str]:
    from scipy import ndimage

    ids = [int(i) for i in np.unique(labels) if i != 0]
    fields: dict[str, str] = {
        "Segmentation_MasterRepresentation": "Binary labelmap",
        "Segmentation_ContainedRepresentationNames": "Binary labelmap|",
        "Segmentation_ReferenceImageExtentOffset": "0 0 0",
        "Segmentation_ConversionParameters": "",
    }
    boxes = ndimage.find_objects(labels) if ids else []
    for n, oid in enumerate(ids):
        r, g, b = object_color_float(oid)
        box = boxes[oid - 1]
        if box is None:  # cannot happen: oid comes from np.unique
            continue
        zs, ys, xs = box
        pre = f"Segment{n}_"
        fields[pre + "ID"] = f"Segment_{oid}"
        fields[pre + "Name"] = names.get(oid, f"Object {oid}")
        fields[pre + "NameAutoGenerated"] = "0" if oid in names else "1"
        fields[pre + "Color"] = f"{r:.6g} {g:.6g} {b:.6g}"
        fields[pre + "ColorAutoGenerated"] = "0"
        fields[pre + "LabelValue"] = str(oid)
        fields[pre + "Layer"] = "0"
        # Extent in (x, y, z) index order, inclusive: x0 x1 y0 y1 z0 z1
        fields[pre + "Extent"] = f"{xs.start} {xs.stop - 1} {ys.start} {ys.stop - 1} {zs.start} {zs.stop - 1}"
        fields[pre + "Tags"] = "Segmentation.Status:inprogress|"
    return fields


def _save_nrrd(p: Path, labels: np.ndarray, volume: Volume, *, seg: bool, names: dict[int, str]) -> None:
    import nrrd

    header: dict = {"type": "uint8", "encoding": "gzip", **nrrd_geometry(volume)}
    if seg:
        header.update(_segment_fields(labels, names))
    with atomic_path(p) as tmp:
        # index_order='F': the array is indexed (x, y, z) and x varies fastest on disk
        nrrd.write(str(tmp), np.asfortranarray(labels.transpose(2, 1, 0)), header, index_order="F", compression_level=6)


# --------------------------------------------------------------------------- loading
def _stat_regular(p: Path) -> os.stat_result:
    return regular_source(p, what="a label-map file")


def _geometry_volume(p: Path, data_xyz: np.ndarray, affine_lps: np.ndarray, fmt: str) -> tuple[np.ndarray, Volume]:
    if not np.all(np.isfinite(affine_lps)):
        raise FormatError(f"{p}: non-finite geometry in the {fmt} header")
    m = affine_lps[:3, :3]
    spacing_xyz = np.linalg.norm(m, axis=0)
    if np.any(spacing_xyz <= 0):
        raise FormatError(f"{p}: degenerate geometry (zero voxel size) in the {fmt} header")
    direction = m / spacing_xyz[None, :]
    if abs(np.linalg.det(direction)) < 1e-6:
        raise FormatError(f"{p}: degenerate geometry (collinear axes) in the {fmt} header")
    if np.abs(direction.T @ direction - np.eye(3)).max() > 1e-3:
        raise FormatError(f"{p}: the {fmt} header's axes are not at right angles (a sheared grid): a label map must "
                          "lie on a rectangular voxel grid; resample it (e.g. 3D Slicer's Resample Scalar Volume)")
    if data_xyz.dtype.kind not in "biuf":
        raise FormatError(f"{p}: label data of type {data_xyz.dtype} is not numeric")
    if data_xyz.dtype.kind == "f":
        if not np.all(np.isfinite(data_xyz)) or np.any(data_xyz != np.round(data_xyz)):
            raise FormatError(f"{p}: label values are not whole numbers")
    if data_xyz.size and (data_xyz.min() < 0 or data_xyz.max() > 255):
        raise FormatError(f"{p}: label values outside 0..255")
    labels = np.ascontiguousarray(data_xyz.transpose(2, 1, 0)).astype(np.uint8, copy=False)
    vol = Volume(
        data=labels,
        spacing=tuple(spacing_xyz[::-1]),
        origin=tuple(affine_lps[:3, 3]),
        direction=direction,
        modality="SEG",
        window=(5.0, 10.0),
        source=f"{p} ({fmt} label map)",
    )
    return labels, vol


def _check_size(p: Path, shape, itemsize: int, file_size: int, *, compressed: bool, offset: int = 0) -> None:
    n = 1
    for s in shape:
        if s < 0:
            raise FormatError(f"{p}: negative dimension in the header {tuple(shape)}")
        n *= int(s)
    if n > MAX_VOXELS:
        raise FormatError(f"{p}: {tuple(shape)} is too large for a label map")
    need = n * itemsize
    # the decoded data, its uint8 copy and the (z, y, x) transpose: against the process's
    # limits (RLIMIT_AS, cgroup), not only the machine's free RAM
    check_allocation(need + 2 * n, what=f"the {'x'.join(str(int(v)) for v in shape)} label map", path=p)
    if compressed:
        if need > (file_size - offset) * DEFLATE_MAX_RATIO + 1024:
            raise FormatError(
                f"{p}: header declares {need} bytes of data, more than the {file_size}-byte compressed file can hold"
            )
    elif need > file_size - offset:
        raise FormatError(f"{p}: truncated: header declares {need} bytes of data after byte {offset}, file has {file_size}")


def load_labels(path: str | os.PathLike) -> tuple[np.ndarray, Volume]:
    """Load a label map (.nii, .nii.gz, .nrrd, .seg.nrrd).

    Returns
    -------
    labels : ndarray (z, y, x) uint8
    volume : Volume
        Geometry from the file (LPS), ``data`` = ``labels``.

    Raises
    ------
    FormatError
        Unreadable, truncated or corrupted file, non-label data (values outside
        0..255 or fractional), not 3D, or degenerate geometry.
    """
    p = Path(path)
    kind = _kind(p)
    st = _stat_regular(p)
    try:
        if kind in ("nii", "nii.gz"):
            return _load_nifti(p, st.st_size, compressed=(kind == "nii.gz"))
        if kind == "gipl":
            return _load_gipl(p)
        return _load_nrrd(p, st.st_size)
    except CtuiError:  # FormatError, or a size the memory limits refuse
        raise
    except MemoryError:
        raise FormatError(f"{p}: not enough memory to load this label map") from None
    except Exception as exc:  # noqa: BLE001 - library errors on corrupt files are many and varied
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise FormatError(f"{p}: corrupted or unsupported label map ({msg})") from None


def _load_nifti(p: Path, file_size: int, *, compressed: bool) -> tuple[np.ndarray, Volume]:
    import nibabel as nib

    img = nib.load(str(p))
    if not isinstance(img, (nib.Nifti1Image, nib.Nifti2Image)):
        raise FormatError(f"{p}: not a NIfTI image")
    shape = tuple(int(s) for s in img.shape)
    if len(shape) == 4 and shape[3] == 1:
        shape3 = shape[:3]
    elif len(shape) == 3:
        shape3 = shape
    else:
        raise FormatError(f"{p}: label map must be 3D, got shape {shape}")
    itemsize = img.get_data_dtype().itemsize
    offset = int(img.dataobj.offset) if hasattr(img.dataobj, "offset") else 0
    _check_size(p, shape, itemsize, file_size, compressed=compressed, offset=0 if compressed else offset)
    if compressed:
        _check_gzip_isize(p, offset + int(np.prod(shape, dtype=np.int64)) * itemsize)
    data = np.asanyarray(img.dataobj)
    if data.ndim == 4:
        data = data[..., 0]
    if data.shape != shape3:
        raise FormatError(f"{p}: data shape {data.shape} differs from the header's {shape3}")
    affine_lps = LPS_TO_RAS @ np.asarray(img.affine, dtype=np.float64)
    return _geometry_volume(p, data, affine_lps, "NIfTI")


def _load_gipl(p: Path) -> tuple[np.ndarray, Volume]:
    """An ITK-SNAP GIPL segmentation: the header's sizes checked against the file's first
    (:func:`ctui.engine.io.series.gipl.read_header`), identity direction as ITK reads it."""
    from ctui.engine.io.series import gipl  # loaded with its format

    hdr = gipl.read_header(p)
    n = int(np.prod(hdr.shape))
    check_allocation(hdr.data_bytes + 2 * n, what=f"the {'x'.join(str(v) for v in hdr.shape[::-1])} label map", path=p)
    data = gipl.read_voxels(p, hdr)
    affine = np.eye(4)
    affine[:3, :3] = np.diag(hdr.spacing_xyz)
    affine[:3, 3] = hdr.origin
    return _geometry_volume(p, data.transpose(2, 1, 0), affine, "GIPL")


def _check_gzip_isize(p: Path, need: int) -> None:
    """A single-member gzip stores its uncompressed size mod 2**32 in its last 4 bytes.

    A mismatch with what the header needs means truncation/corruption; it is only a
    fast pre-check (nibabel verifies the data itself).
    """
    try:
        with open(p, "rb") as fh:
            if fh.read(2) != b"\x1f\x8b":
                raise FormatError(f"{p}: not a gzip file (expected a .nii.gz)")
            fh.seek(-4, os.SEEK_END)
            isize = int.from_bytes(fh.read(4), "little")
    except OSError as exc:
        raise FormatError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if need < 2**32 and isize < need:
        raise FormatError(f"{p}: truncated or corrupted: gzip holds {isize} bytes, the header needs {need}")


def _load_nrrd(p: Path, file_size: int) -> tuple[np.ndarray, Volume]:
    import nrrd

    with open(p, "rb") as fh:
        magic = fh.read(8)
        if not magic.startswith(b"NRRD000"):
            raise FormatError(f"{p}: not an NRRD file (missing NRRD000x magic)")
        fh.seek(0)
        # pynrrd reads text lines; bound the header to 1 MiB of lines
        header = nrrd.read_header(_bounded_lines(fh, p))
        if "data file" in header or "datafile" in header:
            raise FormatError(f"{p}: detached NRRD data files are not supported for label maps")
        dim = int(header.get("dimension", 0))
        sizes = [int(s) for s in np.atleast_1d(header.get("sizes", []))]
        if dim != len(sizes):
            raise FormatError(f"{p}: NRRD dimension {dim} does not match sizes {sizes}")
        if dim == 4 and sizes[0] == 1:
            pass
        elif dim != 3:
            raise FormatError(f"{p}: label map must be 3D, got {dim} dimensions (multi-layer segmentations are not supported)")
        dtype = np.dtype(nrrd.reader._determine_datatype(header))  # noqa: SLF001 - pynrrd's own type table
        encoding = str(header.get("encoding", "raw")).lower()
        compressed = encoding in ("gzip", "gz", "bzip2", "bz2")
        if encoding in ("bzip2", "bz2"):
            # bzip2 can expand far more than deflate; cap generously but finitely
            _check_size(p, sizes, dtype.itemsize, file_size * 50, compressed=True)
        else:
            _check_size(p, sizes, dtype.itemsize, file_size, compressed=compressed, offset=0)
        line_skip = int(header.get("lineskip", header.get("line skip", 0)))
        byte_skip = int(header.get("byteskip", header.get("byte skip", 0)))
        if not (0 <= line_skip <= 1000) or not (-1 <= byte_skip <= file_size):
            raise FormatError(f"{p}: unreasonable NRRD line skip {line_skip} / byte skip {byte_skip}")
        if compressed:
            data = _read_compressed(p, fh, header, sizes, dtype, encoding, line_skip, byte_skip)
        else:
            data = nrrd.read_data(header, fh, str(p), index_order="F")
    if data.ndim == 4:
        data = data[0]
    if tuple(data.shape) != tuple(sizes[-3:]):
        raise FormatError(f"{p}: data shape {data.shape} differs from the header's sizes {sizes}")
    space = str(header.get("space", "left-posterior-superior")).lower()
    if "space directions" in header:
        sd = np.asarray(header["space directions"], dtype=np.float64)
        if sd.shape == (4, 3):  # a 'list' axis has a none row, pynrrd gives nan
            sd = sd[1:]
        if sd.shape != (3, 3):
            raise FormatError(f"{p}: space directions of shape {sd.shape}, expected 3x3")
        m = sd.T.copy()  # columns = index axes
        origin = np.asarray(header.get("space origin", np.zeros(3)), dtype=np.float64).reshape(-1)
        if origin.shape != (3,):
            raise FormatError(f"{p}: space origin must have 3 values")
    else:
        sp = np.asarray(header.get("spacings", [1.0, 1.0, 1.0]), dtype=np.float64).reshape(-1)[-3:]
        m = np.diag(sp)
        origin = np.zeros(3)
    if space in ("right-anterior-superior", "ras"):
        flip = np.diag([-1.0, -1.0, 1.0])
        m = flip @ m
        origin = flip @ origin
    elif space in ("left-anterior-superior", "las"):
        flip = np.diag([1.0, -1.0, 1.0])
        m = flip @ m
        origin = flip @ origin
    elif space not in ("left-posterior-superior", "lps"):
        raise FormatError(f"{p}: unsupported NRRD space {space!r}")
    aff = np.eye(4)
    aff[:3, :3] = m
    aff[:3, 3] = origin
    return _geometry_volume(p, data, aff, "NRRD")


def _read_compressed(p: Path, fh, header, sizes, dtype: np.dtype, encoding: str, line_skip: int, byte_skip: int) -> np.ndarray:
    """Decompress attached gzip/bzip2 NRRD data, never producing more than needed.

    pynrrd decompresses the whole stream; a corrupted or hostile stream could expand
    far beyond the declared size, so this reads with ``max_length``.
    """
    import bz2  # optional in a Python build (as zlib): needed only for compressed NRRD data
    import zlib

    if byte_skip == -1:
        raise FormatError(f"{p}: NRRD byte skip -1 with compressed data is not supported")
    for _ in range(line_skip):
        fh.readline()
    need = int(np.prod(sizes, dtype=np.int64)) * dtype.itemsize
    skip = max(byte_skip, 0)
    if encoding in ("gzip", "gz"):
        dec = zlib.decompressobj(zlib.MAX_WBITS | 32)  # gzip or zlib header
    else:
        dec = bz2.BZ2Decompressor()
    want = need + skip + 1  # one byte more than declared reveals oversized streams
    out = inflate_bounded(fh, dec, want)
    if len(out) > need + skip:
        raise FormatError(f"{p}: compressed data holds more than the {need} bytes the header declares")
    if not dec.eof:
        raise FormatError(f"{p}: truncated or corrupted compressed data (stream ends early)")
    if len(out) - skip != need:
        raise FormatError(f"{p}: truncated: compressed data holds {max(len(out) - skip, 0)} of the {need} bytes the header declares")
    arr = np.frombuffer(out, dtype, count=need // dtype.itemsize, offset=skip)  # no copy
    return arr.reshape(tuple(sizes[::-1])).T


def _bounded_lines(fh, p: Path, limit: int = 1 << 20):
    """Yield header lines (as str) from a binary file, at most ``limit`` bytes.

    pynrrd's read_header stops at the first blank line; the file handle is then left
    at the start of the data.
    """
    total = 0
    while True:
        line = fh.readline(limit - total + 1)
        if not line:
            return
        total += len(line)
        if total > limit:
            raise FormatError(f"{p}: NRRD header longer than {limit} bytes")
        yield line.decode("ascii", errors="replace")
