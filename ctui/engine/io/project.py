"""``.ctui`` project files and autosave.

A project is ONE file: a zip archive (deflate) holding

* ``project.json``: format name and version, source path and options, the source
  series' geometry (shape, spacing, origin, direction), modality, SeriesInstanceUID and
  voxel hash (:func:`source_identity`), pipeline (``Pipeline.to_dict()``), objects (id,
  name, colour, seeds, tolerance/range...), propagation settings, drift corrections,
  window and free metadata: the one schema of :mod:`ctui.engine.io.projectschema`,
  validated field by field on open;
* ``labels.npy``: the label volume (uint8, (z, y, x)), when there is one.

It is written atomically (temporary file in the same folder, fsync, rename), so a
crash during a save leaves the previous complete project. It never holds patient
identifiers: the source is referenced by its path, no DICOM header is copied, and
identifying keys are scrubbed from ``meta`` and ``source_options``
(:mod:`ctui.engine.core.privacy`).

Loading trusts nothing: a corrupt, truncated or foreign file gives a one-line
:class:`~ctui.engine.core.errors.FormatError`, and the label volume is decompressed only
up to the size implied by the shape in ``project.json`` (which must itself be
plausible for the compressed size), so a "zip bomb" cannot exhaust memory.

Autosave: :func:`autosave` writes ``<name>.ctui.autosave`` beside a saved project (or,
for a project not saved yet, a file in ``$CTUI_AUTOSAVE_DIR`` or
``~/.cache/ctui/autosave`` keyed by the source path); :func:`find_autosave` returns it
when it is newer than the project, for recovery.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import weakref
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.atomic import atomic_write, regular_source
from ctui.engine.core.errors import FormatError
from ctui.engine.core.geometry import Geometry
from ctui.engine.core.jsonio import to_jsonable
from ctui.engine.core.limits import check_allocation
from ctui.engine.core.privacy import scrub
from ctui.engine.io.projectschema import FORMAT_NAME, FORMAT_VERSION, SOURCE_OPTION_KEYS, validate

JSON_MEMBER = "project.json"
LABELS_MEMBER = "labels.npy"
#: Largest project.json accepted (bytes, uncompressed).
MAX_JSON_BYTES = 64 * 1024 * 1024
#: Largest label volume accepted (voxels).
MAX_VOXELS = 2**31 - 1
#: deflate cannot expand more than ~1032:1.
DEFLATE_MAX_RATIO = 1032
AUTOSAVE_SUFFIX = ".autosave"


@dataclass(eq=False)
class Project:
    """Everything needed to resume work on a series.

    Attributes
    ----------
    source_path : str
        Path of the source series (folder or file), as given by the user.
    source_options : dict
        Options given to ``loaders.load`` (series uid, spacing, shape, dtype...).
    pipeline : dict
        ``Pipeline.to_dict()``.
    labels : ndarray (z, y, x) uint8 or None
        Label volume: 0 background, 1..10 objects.
    objects : list of dict
        One per object: ``id``, ``name``, ``color``, ``seeds`` [(x, y, z)...],
        tolerance/range and any other settings.
    propagation : dict
        Propagation settings (direction, leak factor, connectivity...).
    drift : dict
        Drift corrections (per-slice shifts) and flags.
    window : (centre, width) or None
        Display window.
    meta : dict
        Free-form extra data (no patient identifiers: identifying keys are dropped).
    geometry : Geometry or None
        The source grid (shape, spacing, origin, direction): measure, mesh, render and
        drift work from the project alone when the series is gone.
    modality, series_uid : str or None
        Of the source series.
    voxel_hash : str or None
        :func:`voxel_hash` of the source voxels: a series that no longer matches is refused.
    version : int
        Format version the project was read from / will be written as.
    """

    source_path: str = ""
    source_options: dict = field(default_factory=dict)
    pipeline: dict = field(default_factory=dict)
    labels: np.ndarray | None = None
    objects: list = field(default_factory=list)
    propagation: dict = field(default_factory=dict)
    drift: dict = field(default_factory=dict)
    window: tuple | None = None
    meta: dict = field(default_factory=dict)
    geometry: Geometry | None = None
    modality: str | None = None
    series_uid: str | None = None
    voxel_hash: str | None = None
    version: int = FORMAT_VERSION

    def to_json_dict(self) -> dict:
        """The JSON part of the project (everything but the label voxels)."""
        d = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "source_path": str(self.source_path),
            "source_options": scrub(self.source_options or {}),
            "pipeline": self.pipeline or {},
            "objects": list(self.objects or []),
            "propagation": self.propagation or {},
            "drift": self.drift or {},
            "window": list(self.window) if self.window is not None else None,
            "meta": scrub(self.meta or {}),
            "geometry": self.geometry.to_dict() if self.geometry is not None else None,
            "modality": self.modality,
            "series_uid": self.series_uid,
            "voxel_hash": self.voxel_hash,
            "labels": None,
        }
        if self.labels is not None:
            d["labels"] = {"member": LABELS_MEMBER, "shape": [int(s) for s in self.labels.shape], "dtype": "uint8"}
        return to_jsonable(d, ndigits=None, strict=True)

    def set_source(self, volume: Any, *, data: np.ndarray | None = None) -> "Project":
        """Record ``volume``'s geometry, modality, series UID and voxel hash (of ``data``
        when given: the voxels as loaded, before a drift correction); returns self."""
        for key, value in source_identity(volume, data=data).items():
            setattr(self, key, value)
        said = [a.to_dict() for a in getattr(volume, "assumptions", [])]
        self.meta = {**{k: v for k, v in (self.meta or {}).items() if k != "assumptions"},
                     **({"assumptions": said} if said else {})}  # what the loader assumed, kept with the labels
        return self

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Project):
            return NotImplemented
        if self.to_json_dict() != other.to_json_dict():
            return False
        if (self.labels is None) != (other.labels is None):
            return False
        return self.labels is None or bool(np.array_equal(self.labels, other.labels))


def voxel_hash(data: np.ndarray) -> str:
    """``blake2b-128:<hex>`` of the voxels (shape, dtype and bytes); ~1 GB/s, cached per array."""
    arr = np.ascontiguousarray(data)
    key = id(data)
    hit = _HASHES.get(key)
    if hit is not None and hit[0]() is data:
        return hit[1]
    h = hashlib.blake2b(digest_size=16)
    h.update(f"{arr.dtype.str}{arr.shape}".encode())
    h.update(memoryview(arr).cast("B"))
    out = "blake2b-128:" + h.hexdigest()
    try:
        _HASHES[key] = (weakref.ref(data), out)
    except TypeError:  # not weak-referenceable: no cache
        pass
    if len(_HASHES) > 64:
        for k in [k for k, (ref, _) in _HASHES.items() if ref() is None]:
            del _HASHES[k]
    return out


_HASHES: dict[int, tuple[Any, str]] = {}


def source_identity(volume: Any, *, data: np.ndarray | None = None) -> dict:
    """The fields of :class:`Project` that tie it to ``volume`` (a Volume; ``data``: its
    voxels as loaded, when ``volume.data`` has been changed since)."""
    uid = None
    idx = (volume.meta or {}).get("series_index")
    if isinstance(idx, int) and 0 <= idx < len(volume.series or []):
        uid = str(volume.series[idx].get("uid") or "") or None
    return {"geometry": Geometry.of(volume), "modality": str(volume.modality or "") or None, "series_uid": uid,
            "voxel_hash": voxel_hash(volume.data if data is None else data)}


def source_load_options(project: Project) -> dict:
    """The recorded loader options, as keyword arguments for ``ctui.engine.io.series.load``."""
    opts = {k: v for k, v in (project.source_options or {}).items() if k in SOURCE_OPTION_KEYS and v is not None}
    for k in ("spacing", "shape", "crop", "downsample"):
        if isinstance(opts.get(k), list):
            opts[k] = tuple(opts[k])
    return opts


# --------------------------------------------------------------------------- save
def encode_project(project: Project, *, compresslevel: int = 6) -> bytes:
    """The bytes of a ``.ctui`` file for ``project`` (see :func:`save_project`)."""
    labels = project.labels
    if labels is not None:
        labels = np.asarray(labels)
        if labels.ndim != 3:
            raise FormatError(f"project labels must be 3D (z, y, x), got shape {labels.shape}")
        if labels.dtype != np.uint8:
            if labels.size and (labels.min() < 0 or labels.max() > 255):
                raise FormatError("project labels must be in 0..255")
            labels = labels.astype(np.uint8)
    try:
        meta = project.to_json_dict()
    except TypeError as exc:
        raise FormatError(f"project cannot be saved: {exc}") from None
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=compresslevel) as zf:
        zf.writestr(JSON_MEMBER, json.dumps(meta, indent=1, sort_keys=True))
        if labels is not None:
            with zf.open(LABELS_MEMBER, "w", force_zip64=labels.nbytes > 2**31) as fh:
                np.lib.format.write_array(fh, np.ascontiguousarray(labels), allow_pickle=False)
    return buf.getvalue()


def save_project(path: str | os.PathLike, project: Project, *, compresslevel: int = 6) -> Path:
    """Write ``project`` to ``path`` (a single ``.ctui`` file) atomically.

    Raises
    ------
    FormatError
        Labels not 3D / not 0..255, or a field that cannot be stored as JSON.
    CtuiError
        The file cannot be written (disk full, permission denied...); the previous
        file, if any, is left intact and no partial file remains.
    """
    data = encode_project(project, compresslevel=compresslevel)
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return Path(path)


# --------------------------------------------------------------------------- load
def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, n: int) -> bytes:
    """Read exactly ``n`` bytes of a member and check it ends there (CRC verified)."""
    with zf.open(info) as fh:
        data = fh.read(n)
        extra = fh.read(1)
    if len(data) != n or extra:
        raise zipfile.BadZipFile(f"member {info.filename} is {'shorter' if len(data) != n else 'longer'} than declared")
    return data


def _expect(cond: bool, p: Path, msg: str) -> None:
    if not cond:
        raise FormatError(f"{p}: not a valid ctui project: {msg}")


def load_project(path: str | os.PathLike, *, with_labels: bool = True) -> Project:
    """Load a ``.ctui`` project (or autosave) written by :func:`save_project`; without its
    labels (``labels`` None: project.json only, validated) unless ``with_labels``.

    Raises
    ------
    FormatError
        Missing/unreadable, truncated, corrupted or foreign file, a newer format
        version, or labels inconsistent with project.json.
    """
    p = Path(path)
    st = regular_source(p, what="a ctui project")
    try:
        with open(p, "rb") as fh:
            head = fh.read(4)
        _expect(head == b"PK\x03\x04", p, "not a zip archive" if len(head) == 4 else "file is empty or truncated")
        with zipfile.ZipFile(p) as zf:
            return _load_zip(p, zf, st.st_size, with_labels=with_labels)
    except FormatError:
        raise
    except MemoryError:
        raise FormatError(f"{p}: not enough memory to load this project") from None
    except OSError as exc:
        raise FormatError(f"{p}: cannot read ({exc.strerror or exc})") from None
    except Exception as exc:  # noqa: BLE001 - zipfile/zlib/json/numpy raise many types on corrupt input
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise FormatError(f"{p}: corrupted ctui project ({msg})") from None


def _load_zip(p: Path, zf: zipfile.ZipFile, file_size: int, *, with_labels: bool = True) -> Project:
    infos = {i.filename: i for i in zf.infolist()}
    _expect(JSON_MEMBER in infos, p, f"{JSON_MEMBER} is missing")
    ji = infos[JSON_MEMBER]
    _expect(0 < ji.file_size <= MAX_JSON_BYTES, p, f"{JSON_MEMBER} size {ji.file_size} out of range")
    _expect(ji.file_size <= ji.compress_size * DEFLATE_MAX_RATIO + 1024, p, f"{JSON_MEMBER} declared size is implausible")
    try:
        meta = json.loads(_read_member(zf, ji, ji.file_size).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(f"{p}: not a valid ctui project: {JSON_MEMBER} is not JSON ({exc})") from None
    version, geometry = validate(meta, p)
    window = meta.get("window")
    labels = _read_labels(p, zf, infos, meta.get("labels"), file_size) if with_labels else None
    return Project(
        source_path=meta.get("source_path") or "",
        source_options=meta.get("source_options") or {},
        pipeline=meta.get("pipeline") or {},
        labels=labels,
        objects=meta.get("objects") or [],
        propagation=meta.get("propagation") or {},
        drift=meta.get("drift") or {},
        window=(window[0], window[1]) if window is not None else None,
        meta=meta.get("meta") or {},
        geometry=geometry,  # version 1: from meta's spacing_zyx_mm... when recorded
        modality=meta.get("modality"),
        series_uid=meta.get("series_uid"),
        voxel_hash=meta.get("voxel_hash"),
        version=version,
    )


def _read_labels(p: Path, zf: zipfile.ZipFile, infos: dict, lab: Any, file_size: int) -> np.ndarray | None:
    """The label volume of the ``labels`` entry, read within the bounds it declares."""
    if lab is None:
        return None
    _expect(isinstance(lab, dict), p, "labels entry must be an object")
    shape = lab.get("shape")
    _expect(
        isinstance(shape, list) and len(shape) == 3 and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape),
        p,
        f"bad labels shape {shape!r}",
    )
    _expect(lab.get("dtype") == "uint8", p, f"labels dtype {lab.get('dtype')!r} is not uint8")
    n = int(np.prod(shape, dtype=np.int64))
    _expect(n <= MAX_VOXELS, p, f"labels shape {shape} too large")
    if n >= 256 * 1024 * 1024:
        check_allocation(n, what="the project's labels", path=p, fraction=0.5)
    member = lab.get("member", LABELS_MEMBER)
    _expect(isinstance(member, str) and member in infos, p, f"{member} is missing")
    li = infos[member]
    # an .npy header is 64..~4096 bytes; the data must be exactly n bytes
    _expect(n <= li.file_size <= n + 4096 + 64, p, f"{member} size {li.file_size} does not match labels shape {shape}")
    _expect(li.file_size <= li.compress_size * DEFLATE_MAX_RATIO + 4096, p, f"{member} declared size is implausible for its compressed size")
    _expect(li.compress_size <= file_size, p, f"{member} is larger than the file (truncated?)")
    raw = _read_member(zf, li, li.file_size)
    fh = io.BytesIO(raw)
    major, minor = np.lib.format.read_magic(fh)
    if (major, minor) == (1, 0):
        hshape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
    else:
        hshape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
    _expect(list(hshape) == shape and dtype == np.uint8 and not fortran, p, f"{member} header {hshape} {dtype} differs from project.json")
    off = fh.tell()
    _expect(len(raw) - off == n, p, f"{member} holds {len(raw) - off} bytes, shape {shape} needs {n}")
    return np.frombuffer(raw, np.uint8, count=n, offset=off).reshape(shape).copy()


# --------------------------------------------------------------------------- autosave
def _autosave_dir() -> Path:
    env = os.environ.get("CTUI_AUTOSAVE_DIR")
    if env:
        return Path(env)
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "ctui" / "autosave"


def autosave_path(project_path_or_source: str | os.PathLike) -> Path:
    """Where the autosave for a project (``x.ctui``) or an unsaved source goes.

    * ``/a/b/x.ctui`` -> ``/a/b/x.ctui.autosave`` (beside the project);
    * a source path (series folder or file) -> ``<autosave dir>/<name>-<hash>.ctui.autosave``
      where the autosave dir is ``$CTUI_AUTOSAVE_DIR`` or ``~/.cache/ctui/autosave``
      (the source folder may be read-only) and the hash keys the absolute path.
    """
    p = Path(project_path_or_source)
    if p.name.endswith(".ctui"):
        return p.with_name(p.name + AUTOSAVE_SUFFIX)
    if p.name.endswith(".ctui" + AUTOSAVE_SUFFIX):
        return p
    absolute = os.path.abspath(os.fspath(p))
    key = hashlib.sha1(absolute.encode("utf-8", "surrogateescape")).hexdigest()[:12]
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", p.name)[:40].strip("._") or "source"
    return _autosave_dir() / f"{stem}-{key}.ctui{AUTOSAVE_SUFFIX}"


def autosave(project: Project, project_path_or_source: str | os.PathLike | None = None) -> Path:
    """Write ``project`` to its autosave file atomically (fast compression).

    ``project_path_or_source`` defaults to ``project.source_path``. Returns the path.
    """
    target = autosave_path(project_path_or_source if project_path_or_source is not None else project.source_path)
    if not target.parent.exists():
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FormatError(f"{target.parent}: cannot create the autosave folder ({exc.strerror or exc})") from None
    return save_project(target, project, compresslevel=1)


def find_autosave(project_path_or_source: str | os.PathLike) -> Path | None:
    """The autosave to offer for recovery, or None.

    Returned only if it exists and is newer than the project file (when the argument
    is a ``.ctui`` project that exists).
    """
    a = autosave_path(project_path_or_source)
    try:
        ast = a.stat()
    except OSError:
        return None
    p = Path(project_path_or_source)
    if p.name.endswith(".ctui"):
        try:
            if p.stat().st_mtime_ns >= ast.st_mtime_ns:
                return None
        except OSError:
            pass
    return a


def remove_autosave(project_path_or_source: str | os.PathLike) -> None:
    """Delete the autosave (after an explicit save or when recovery is declined)."""
    try:
        autosave_path(project_path_or_source).unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise FormatError(f"{autosave_path(project_path_or_source)}: cannot remove ({exc.strerror or exc})") from None
