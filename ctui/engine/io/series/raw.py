"""Headerless raw data: one file holding a (z, y, x) volume (or (y, x) slices, z from
the size), or one file per slice (CThead.1 .. CThead.113), read slice by slice into one
preallocated array with crop/downsample applied while reading. Also the data reader of
NIfTI, NRRD and MetaImage files (their geometry given by the caller)."""

from __future__ import annotations

import os
import zlib
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ctui.engine.core.errors import CtuiError, LoadError
from ctui.engine.core.volume import Volume
from ctui.engine.io.series._common import Plan, allocate, check_memory, make_plan, natural_key, rel, run_parallel
from ctui.engine.io.series.stacks import _finish, parse_dtype, parse_shape, parse_spacing


def _read_slices_into(out: np.ndarray, reader: Callable[[int], np.ndarray], zsel: list[int], plan, progress) -> list[tuple[int, str]]:
    def work(k: int, zi: int) -> str | None:
        arr = reader(zi)
        out[k] = arr[plan.y, plan.x]
        return None

    return run_parallel(zsel, work, progress=progress)


def _slice_at(file: Path, offset: int, shape_yx: tuple[int, int], dt: np.dtype) -> tuple[np.ndarray, int]:
    """The (ny, nx) slice of ``dt`` values at byte ``offset`` of ``file``, and the number of
    bytes read (fewer than the slice's: the file is truncated)."""
    buf = np.empty(shape_yx[0] * shape_yx[1], dtype=dt)
    with open(file, "rb") as fh:
        fh.seek(offset)
        got = fh.readinto(memoryview(buf).cast("B"))
    return buf.reshape(shape_yx), got


def _read_planned(full: tuple[int, int, int], native: np.dtype, reader: Callable[[int], np.ndarray], *, crop: Any,
                  downsample: Any, path: Path, memory_limit: int | None,
                  progress: Any) -> tuple[np.ndarray, Plan, list[int], list[tuple[int, str]]]:
    """Read the (nz, ny, nx) volume ``full`` through ``reader(z) -> (ny, nx)`` as cropped and
    downsampled (``crop``, ``downsample``), after checking the output against the memory
    limit: (data, plan, the source slices read, failures as (index in those, reason))."""
    plan = make_plan(full, crop=crop, downsample=downsample, path=path)
    oshape = plan.out_shape(full)
    check_memory(int(np.prod(oshape)) * native.itemsize, shape=oshape, path=path, limit=memory_limit)
    out = allocate(oshape, native)
    zsel = list(range(*plan.z.indices(full[0])))
    return out, plan, zsel, _read_slices_into(out, reader, zsel, plan, progress)


def load_raw(
    path: Path,
    files: Sequence[Path] | None,
    *,
    shape: Any,
    dtype: Any,
    spacing: Any = None,
    offset: int | None = None,
    base: Path | None = None,
    skipped: list[dict[str, str]],
    crop: Any = None,
    downsample: Any = None,
    progress: Callable[[int, int], Any] | None = None,
    memory_limit: int | None = None,
    modality: str = "OT",
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    direction: Any = None,
    source_kind: str = "raw",
    zlib_compressed: bool = False,
    warnings: list[str] | None = None,
    keep_order: bool = False,
) -> Volume:
    """Headerless raw data: one file holding a (z, y, x) volume, or per-slice files.

    ``files`` None: ``path`` is one file; shape (z, y, x), or (y, x) with z taken from
    the file size. Otherwise every file is one (y, x) slice (natural name order); files
    of another size are skipped with a reason. ``offset``: header bytes to skip
    (default: none, or the surplus at the start of a single file, with a warning).
    ``keep_order``: per-slice files in the order given (a MetaImage LIST), not sorted.
    """
    shp = parse_shape(shape, path)
    if shp is None:
        raise CtuiError("raw data needs a shape: (z, y, x) for one file, (y, x) for one file per slice, "
                        "and a data type", path=path, option="shape")
    dt = parse_dtype(dtype, path)
    warnings = list(warnings or [])
    native = dt.newbyteorder("=")
    if files is None:
        out, plan, full, n_src = _raw_one_file(path, shp, dt, native, offset=offset, zlib_compressed=zlib_compressed,
                                               crop=crop, downsample=downsample, progress=progress,
                                               memory_limit=memory_limit, warnings=warnings)
    else:
        out, plan, full, n_src = _raw_slice_files(path, files, shp, dt, native, offset=offset, base=base,
                                                  skipped=skipped, keep_order=keep_order, crop=crop,
                                                  downsample=downsample, progress=progress,
                                                  memory_limit=memory_limit, warnings=warnings)
    nz, ny, nx = full
    sp = parse_spacing(spacing, path)
    kind = f"{source_kind} {dt.str}" if files is None else f"{n_src} raw slice files ({dt.str})"
    meta = {"format": source_kind if files is None else "raw-slices", "dtype": dt.str, "files": n_src}
    return _finish(out, spacing=sp, given=sp is not None, warnings=warnings,
                   source=f"{kind}, {nz}x{ny}x{nx}, from {path}", path=path, meta=meta, skipped=skipped,
                   modality=modality, origin=origin, direction=direction, plan=plan, full=full, what="raw data")


def _inflate(path: Path, offset: int, expected: int) -> bytes:
    """zlib-decompress a MetaImage's data, never producing more than ``expected`` bytes."""
    d = zlib.decompressobj()
    out = bytearray()
    try:
        with open(path, "rb") as fh:
            fh.seek(offset)
            while True:
                chunk = fh.read(1 << 20)
                if not chunk:
                    break
                out += d.decompress(chunk, max(0, expected - len(out)) or 1)
                if len(out) >= expected:
                    break
    except zlib.error as exc:  # corrupted stream (found by FMT's tests/fuzz/test_fuzz_stacks.py)
        raise LoadError(f"corrupted compressed data ({exc})", path=path) from None
    return bytes(out[:expected])




def _raw_one_file(path: Path, shp: tuple[int, ...], dt: np.dtype, native: np.dtype, *, offset: int | None,
                  zlib_compressed: bool, crop: Any, downsample: Any, progress: Any, memory_limit: int | None,
                  warnings: list[str]) -> tuple[np.ndarray, Plan, tuple[int, int, int], int]:
    """One file holding a (z, y, x) volume, or (y, x) slices with z from the size:
    (data, plan, full shape, number of source files)."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise LoadError(f"cannot read ({exc.strerror or exc})", path=path) from None
    ny, nx = shp[-2:]
    slice_bytes = ny * nx * dt.itemsize
    raw_bytes = None
    if zlib_compressed:
        nz = shp[0] if len(shp) == 3 else 1
        raw_bytes = _inflate(path, offset or 0, nz * slice_bytes)
        size_avail = len(raw_bytes)
        off = 0
    else:
        off = int(offset or 0)
        size_avail = size - off
    if len(shp) == 2:
        if size_avail < slice_bytes or size_avail % slice_bytes:
            raise LoadError(f"file size {size_avail} bytes is not a whole number of {ny}x{nx} {dt} slices "
                            f"({slice_bytes} bytes each)", path=path)
        nz = size_avail // slice_bytes
    else:
        nz = shp[0]
    need = nz * slice_bytes
    if size_avail < need:
        raise LoadError(f"file has {size_avail} bytes of data but shape {nz}x{ny}x{nx} {dt} needs {need}", path=path)
    if size_avail > need and offset is None and not zlib_compressed:
        off = size_avail - need
        warnings.append(f"file is {off} bytes larger than the data: the first {off} bytes taken as a header")
    full = (nz, ny, nx)

    def reader(zi: int) -> np.ndarray:
        if raw_bytes is not None:
            return np.frombuffer(raw_bytes, dtype=dt, count=ny * nx, offset=zi * slice_bytes).reshape(ny, nx)
        img, got = _slice_at(path, off + zi * slice_bytes, (ny, nx), dt)
        if got != slice_bytes:
            raise CtuiError(f"truncated at slice {zi}")
        return img

    out, plan, zsel, failures = _read_planned(full, native, reader, crop=crop, downsample=downsample, path=path,
                                              memory_limit=memory_limit, progress=progress)
    if failures:
        raise LoadError(f"cannot read slice {zsel[failures[0][0]]}: {failures[0][1]}", path=path)
    n_src = 1
    return out, plan, full, n_src


def _raw_slice_files(path: Path, files: Sequence[Path], shp: tuple[int, ...], dt: np.dtype, native: np.dtype, *,
                     offset: int | None, base: Path | None, skipped: list[dict[str, str]], keep_order: bool,
                     crop: Any, downsample: Any, progress: Any, memory_limit: int | None,
                     warnings: list[str]) -> tuple[np.ndarray, Plan, tuple[int, int, int], int]:
    """One (y, x) slice per file; files of another size are skipped with a reason:
    (data, plan, full shape, number of source files)."""
    ny, nx = shp[-2:]
    slice_bytes = ny * nx * dt.itemsize
    off = int(offset or 0)
    good_files = []
    for p in (list(files) if keep_order else sorted(files, key=lambda p: natural_key(rel(p, base)))):
        try:
            size = p.stat().st_size
        except OSError as exc:
            skipped.append({"file": rel(p, base), "reason": f"cannot read ({exc.strerror or exc})"})
            continue
        if size - off != slice_bytes:
            skipped.append({"file": rel(p, base), "reason": f"size {size} bytes, expected {slice_bytes + off} "
                            f"for a {ny}x{nx} {dt} slice"})
            continue
        if not os.access(p, os.R_OK):
            skipped.append({"file": rel(p, base), "reason": "cannot read (permission denied)"})
            continue
        good_files.append(p)
    if len(shp) == 3 and shp[0] != len(good_files):
        warnings.append(f"shape says {shp[0]} slices, {len(good_files)} slice files found: loaded those")
    if not good_files:
        raise LoadError(f"no file of {slice_bytes} bytes (one {ny}x{nx} {dt} slice)", path=path)
    nz = len(good_files)
    full = (nz, ny, nx)

    def reader(zi: int) -> np.ndarray:
        img, got = _slice_at(good_files[zi], off, (ny, nx), dt)
        if got != slice_bytes:
            raise CtuiError(f"truncated ({got} of {slice_bytes} bytes)")
        return img

    out, plan, zsel, failures = _read_planned(full, native, reader, crop=crop, downsample=downsample, path=path,
                                              memory_limit=memory_limit, progress=progress)
    bad = {k for k, _ in failures}
    for k, reason in failures:
        skipped.append({"file": rel(good_files[zsel[k]], base), "reason": reason})
    if bad:
        good = [k for k in range(len(zsel)) if k not in bad]
        if not good:
            raise LoadError("no slice file could be read", path=path)
        for j, k in enumerate(good):
            out[j] = out[k]
        out = out[: len(good)]
    n_src = nz
    return out, plan, full, n_src
