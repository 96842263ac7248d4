"""Fuzz the label-map reader (ctui.engine.io.labels.load_labels): .nii, .nii.gz, .nrrd,
.seg.nrrd: truncations, flips, random/hypothesis mutations, and structured header
mutations (NIfTI dim/datatype/vox_offset/pixdim/affine fields, NRRD header fields)."""

from __future__ import annotations

import pytest

import gzip
import struct

import numpy as np

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign


def warm_up() -> None:
    import hypothesis  # noqa: F401
    import nibabel  # noqa: F401
    import nrrd  # noqa: F401
    import scipy.ndimage  # noqa: F401

    import ctui.engine.io.labels  # noqa: F401


def seeds(ctx) -> dict[str, bytes]:
    from ctui.engine.io.labels import save_labels
    from ctui.engine.core.volume import Volume

    labels = np.zeros((3, 4, 5), np.uint8)
    labels[1, 1:3, 1:4] = 2
    labels[2, 3, 4] = 7
    vol = Volume(data=labels, spacing=(2.0, 0.5, 0.7), origin=(1, 2, 3))
    out = {}
    for ext in ("nii", "nii.gz", "nrrd", "seg.nrrd"):
        out[ext] = save_labels(ctx.tmp(f"seed.{ext}"), labels, vol).read_bytes()
    return out


NIFTI_FIELDS = [  # (offset, struct format) in the NIfTI-1 header
    (0, "<i"),  # sizeof_hdr
    *[(40 + 2 * i, "<h") for i in range(8)],  # dim[0..7]
    (70, "<h"),  # datatype
    (72, "<h"),  # bitpix
    *[(76 + 4 * i, "<f") for i in range(8)],  # pixdim
    (108, "<f"),  # vox_offset
    (112, "<f"),  # scl_slope
    (116, "<f"),  # scl_inter
    (252, "<h"),  # qform_code
    (254, "<h"),  # sform_code
    *[(256 + 4 * i, "<f") for i in range(6)],  # quatern b,c,d, qoffset x,y,z
    *[(280 + 4 * i, "<f") for i in range(12)],  # srow_x, srow_y, srow_z
    (344, "<4s"),  # magic
]
INT_VALUES = [-(2**15), -1, 0, 1, 2, 3, 4, 5, 7, 8, 16, 32, 64, 128, 255, 256, 2**15 - 1]
FLOAT_VALUES = [float("nan"), float("inf"), -float("inf"), 0.0, -1.0, 1e-30, 1e30, 3.4e38, 352.0, 2.0**31]
NRRD_LINES = {
    "type": ["uint8", "int8", "float", "double", "int64", "block", "nonsense", ""],
    "dimension": ["0", "1", "2", "3", "4", "16", "-3", "1e9", "x"],
    "sizes": ["5 4 3", "0 4 3", "-5 4 3", "5 4", "5 4 3 1", "65536 65536 65536", "9999999999 1 1", "5 4 x", "nan 1 1"],
    "encoding": ["gzip", "raw", "ascii", "bzip2", "hex", "zip", "gz"],
    "space": ["left-posterior-superior", "right-anterior-superior", "left-anterior-superior", "scanner-xyz", "3D-right-handed", "x"],
    "space directions": ["(1,0,0) (0,1,0) (0,0,1)", "(0,0,0) (0,0,0) (0,0,0)", "(nan,0,0) (0,1,0) (0,0,1)", "(1,0,0) (1,0,0) (0,0,1)", "none (1,0,0) (0,1,0)", "(1,0) (0,1)", "x"],
    "space origin": ["(0,0,0)", "(nan,nan,nan)", "(1,2)", "(1e308,1e308,1e308)", "x"],
    "kinds": ["domain domain domain", "list domain domain", "x"],
    "endian": ["little", "big", "middle"],
    "byte skip": ["0", "-1", "1", "99999999999", "-5"],
    "line skip": ["0", "1", "9999999999999", "-1"],
    "data file": ["x.raw", "/dev/zero", "LIST", "."],
    "spacings": ["1 1 1", "nan 1 1", "0 0 0"],
}


def _nrrd_variant(seed: bytes, field: str, value: str) -> bytes:
    head, sep, data = seed.partition(b"\n\n")
    lines = head.decode().split("\n")
    out, done = [], False
    for line in lines:
        if line.split(":", 1)[0] == field:
            out.append(f"{field}: {value}")
            done = True
        else:
            out.append(line)
    if not done:
        out.append(f"{field}: {value}")
    return "\n".join(out).encode() + sep + data


def campaign(ctx) -> None:
    from ctui.engine.io.labels import load_labels

    s = seeds(ctx)
    for ext, seed in s.items():
        standard_campaign(ctx, load_labels, seed, name=f"x.{ext}", tag=ext.replace(".", ""), flips_every=1 if len(seed) < 300 else 3, trunc_limit=400)
    # structured NIfTI header mutations (uncompressed and gzip)
    nii = s["nii"]
    for off, fmt in NIFTI_FIELDS:
        values = [b"n+1\0", b"ni1\0", b"n+2\0", b"\0\0\0\0"] if fmt == "<4s" else (FLOAT_VALUES if fmt == "<f" else INT_VALUES + ([348, 540, 2**31 - 1, -(2**31)] if fmt == "<i" else []))
        for v in values:
            b = bytearray(nii)
            struct.pack_into(fmt, b, off, v)
            ctx.check(load_labels, bytes(b), name="x.nii", tag="nii-field")
            ctx.check(load_labels, gzip.compress(bytes(b)), name="x.nii.gz", tag="niigz-field")
    # structured NRRD header mutations
    for ext in ("nrrd", "seg.nrrd"):
        for field, values in NRRD_LINES.items():
            for v in values:
                ctx.check(load_labels, _nrrd_variant(s[ext], field, v), name=f"x.{ext}", tag="nrrd-field")
    # ASCII / raw encodings with wrong amounts of data
    head = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nencoding: ascii\n\n"
    for body in (b"", b"1 2 3", b" ".join(b"1" for _ in range(60)), b"x y z", b"1e308 " * 60, b"-1 " * 60):
        ctx.check(load_labels, head + body, name="x.nrrd", tag="nrrd-ascii")
    head = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nencoding: raw\n\n"
    for n in (0, 1, 59, 60, 61, 10000):
        ctx.check(load_labels, head + bytes(n), name="x.nrrd", tag="nrrd-raw")
    # a gzip bomb behind a plausible header
    bomb = gzip.compress(bytes(64 * 2**20))
    ctx.check(load_labels, b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nencoding: gzip\n\n" + bomb, name="x.nrrd", tag="nrrd-bomb", mem_budget=4 * 64 * 2**20)
    ctx.check(load_labels, b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4096 4096 4\nencoding: gzip\n\n" + bomb, name="x.nrrd", tag="nrrd-bomb", mem_budget=4 * 64 * 2**20)
    b = bytearray(nii)
    struct.pack_into("<8h", b, 40, 3, 4096, 4096, 4, 1, 1, 1, 1)
    ctx.check(load_labels, gzip.compress(bytes(b[:352]) + bytes(64 * 2**20)), name="x.nii.gz", tag="niigz-bomb", mem_budget=4 * 64 * 2**20)
    # not files
    d = ctx.tmp("dir.nii.gz")
    d.mkdir(exist_ok=True)
    ctx.check(load_labels, d, tag="labels-dir")
    loop = ctx.tmp("loop.nrrd")
    if not loop.is_symlink():
        loop.symlink_to(loop.name)
    ctx.check(load_labels, loop, tag="labels-symlink-loop", size_hint=0)


@pytest.mark.slow
def test_fuzz_labels():
    res = run_campaign("test_fuzz_labels", "campaign", examples=fuzz_examples(150))
    assert_clean("labels", res, min_cases=4000)
