"""Fuzz the non-DICOM loaders behind ctui.engine.io.series.load: image stacks (PNG
folder, single images, multi-page TIFF, BMP), raw volumes (shape/dtype vs file size),
MetaImage (.mhd + .raw, .mha: structured header mutations such as huge DimSize,
bad ElementType, ElementDataFile pointing at /dev/zero or itself) and NIfTI/NRRD
volumes. Same rule and harness as the other fuzzers (see test_fuzz_harness)."""

from __future__ import annotations

import pytest

import io
from pathlib import Path

import numpy as np

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign

try:
    import ctui.engine.io.series  # noqa: F401

    HAVE_LOADERS = True
except ImportError:  # pragma: no cover
    HAVE_LOADERS = False


def warm_up() -> None:
    import tempfile

    import hypothesis  # noqa: F401
    import nibabel  # noqa: F401
    import nrrd  # noqa: F401
    from PIL import Image  # noqa: F401

    from ctui.engine.io.series import load

    d = Path(tempfile.mkdtemp(prefix="ctui-fuzz-warm-"))
    for name, data in seeds().items():
        (d / name).write_bytes(data)
    for name in ("a.png", "stack.tif", "v.mha", "v.nii.gz", "v.nrrd"):
        try:
            load(d / name)
        except Exception:  # noqa: BLE001 - warm-up only
            pass


def _png(arr) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    return buf.getvalue()


def seeds() -> dict[str, bytes]:
    from PIL import Image

    rng = np.random.default_rng(4)
    out = {}
    img = (rng.random((16, 16)) * 255).astype(np.uint8)
    out["a.png"] = _png(img)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="BMP")
    out["a.bmp"] = buf.getvalue()
    pages = [Image.fromarray((rng.random((16, 16)) * 4000).astype(np.uint16)) for _ in range(3)]
    buf = io.BytesIO()
    pages[0].save(buf, format="TIFF", save_all=True, append_images=pages[1:])
    out["stack.tif"] = buf.getvalue()
    vol = (np.arange(3 * 16 * 16).reshape(3, 16, 16) % 2000 - 1000).astype(np.int16)
    out["v.raw"] = vol.tobytes()
    out["v.mhd"] = (
        b"ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
        b"CompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = -10 -20 5\n"
        b"ElementSpacing = 0.7 0.7 2.5\nDimSize = 16 16 3\nElementType = MET_SHORT\nElementDataFile = v.raw\n"
    )
    out["v.mha"] = out["v.mhd"].replace(b"ElementDataFile = v.raw", b"ElementDataFile = LOCAL") + vol.tobytes()
    import gzip

    import nibabel as nib

    nimg = nib.Nifti1Image(vol.transpose(2, 1, 0).copy(), np.diag([-0.7, -0.7, 2.5, 1.0]))
    out["v.nii.gz"] = gzip.compress(nimg.to_bytes())
    import nrrd

    buf = io.BytesIO()
    nrrd.write(buf, vol.transpose(2, 1, 0).copy(), {"encoding": "gzip", "space": "left-posterior-superior",
                                                    "space directions": np.diag([0.7, 0.7, 2.5]), "space origin": [0, 0, 0]})
    out["v.nrrd"] = buf.getvalue()
    return out


MHD_FIELDS = {
    "NDims": ["0", "1", "2", "4", "-3", "999999", "x"],
    "DimSize": ["16 16 3", "0 16 3", "-16 16 3", "16 16", "16 16 3 1", "100000 100000 100000", "4294967296 1 1", "16 16 x", "1e9 1 1"],
    "ElementType": ["MET_UCHAR", "MET_FLOAT", "MET_DOUBLE", "MET_LONG_LONG", "MET_SHORT_ARRAY", "MET_STRING", "MET_NONE", ""],
    "ElementNumberOfChannels": ["0", "3", "-1", "100000"],
    "ElementSpacing": ["0 0 0", "-1 1 1", "nan 1 1", "inf 1 1", "1e308 1e308 1e308", "1", "a b c"],
    "Offset": ["nan nan nan", "1 2", "1e308 0 0", "x"],
    "TransformMatrix": ["0 0 0 0 0 0 0 0 0", "1 0 0 1 0 0 0 0 1", "nan 0 0 0 1 0 0 0 1", "1 0 0"],
    "BinaryDataByteOrderMSB": ["True", "False", "maybe"],
    "CompressedData": ["True", "False", "x"],
    "CompressedDataSize": ["0", "10", "-1", "99999999999"],
    "HeaderSize": ["-1", "0", "10", "99999999999", "-99"],
    "ElementDataFile": ["v.raw", "LOCAL", "missing.raw", "/dev/zero", "/dev/urandom", "v.mhd", ".", "LIST", "LIST 2D", "slice%03d.raw 0 2 1", "../../../../etc/hostname", ""],
}


def _mhd_variant(seed: bytes, field: str, value: str) -> bytes:
    lines = seed.decode().splitlines()
    out, done = [], False
    for ln in lines:
        if ln.split("=", 1)[0].strip() == field:
            out.append(f"{field} = {value}")
            done = True
        else:
            out.append(ln)
    if not done:
        out.insert(len(out) - 1, f"{field} = {value}")
    # ElementDataFile must stay last
    last = [ln for ln in out if ln.startswith("ElementDataFile")]
    out = [ln for ln in out if not ln.startswith("ElementDataFile")] + last
    return ("\n".join(out) + "\n").encode()


def campaign(ctx) -> None:
    from ctui.engine.io.series import load

    s = seeds()
    n = ctx.examples
    # single images and multi-page TIFF
    for name in ("a.png", "a.bmp", "stack.tif"):
        standard_campaign(ctx, load, s[name], name=name, tag=name.split(".")[1], flips_every=4, trunc_limit=120)
    # a folder of PNG slices with one broken
    folder = ctx.tmp("case/pngs/a0.png").parent
    for i in (0, 2):
        (folder / f"a{i}.png").write_bytes(s["a.png"])

    def load_folder(p: Path):
        return load(p.parent)

    from test_fuzz_harness import mutate, truncations

    rng = np.random.default_rng(8)
    for t in truncations(s["a.png"], 60):
        ctx.check(load_folder, t, name="pngs/a1.png", tag="png-folder")
    for _ in range(n // 4):
        ctx.check(load_folder, mutate(s["a.png"], rng), name="pngs/a1.png", tag="png-folder")
    # a PNG of a different size in the folder
    ctx.check(load_folder, _png(np.zeros((17, 16), np.uint8)), name="pngs/a1.png", tag="png-folder")
    # huge declared image dimensions (PNG IHDR, BMP header)
    import struct
    import zlib

    png = bytearray(s["a.png"])
    for w, h in ((65535, 65535), (2**31 - 1, 1), (1, 2**31 - 1), (0, 16)):
        b = bytearray(png)
        struct.pack_into(">II", b, 16, w, h)
        struct.pack_into(">I", b, 29, zlib.crc32(bytes(b[12:29])) & 0xFFFFFFFF)  # fix the IHDR CRC
        ctx.check(load, bytes(b), name="big.png", tag="png-huge-dims")
    for w, h in ((65535, 65535), (2**31 - 1, 1), (-16, -16)):
        b = bytearray(s["a.bmp"])
        struct.pack_into("<ii", b, 18, w, h)
        ctx.check(load, bytes(b), name="big.bmp", tag="bmp-huge-dims")
    # raw: shape/dtype against the file size
    raw = s["v.raw"]

    def raw_loader(shape, dtype, offset=None):
        return lambda p: load(p, shape=shape, dtype=dtype, offset=offset)

    for shape, dtype, offset in (
        ((3, 16, 16), "int16", None), ((3, 16, 16), ">u2", None), ((16, 16), "int16", None), ((3, 16, 17), "int16", None),
        ((1000, 1000, 1000), "uint8", None), ((2**20, 2**20, 2**20), "float64", None), ((3, 16, 16), "int16", 10**12),
        ((3, 16, 16), "int16", -5), ((3, 16, 16), "complex128", None), ((3, 16, 16), "object", None), ((3, 16, 16), "V7", None),
        ((0, 16, 16), "int16", None), ((3, 16, 16), "float32", 2),
    ):
        for data in (raw, raw[:100], b""):
            ctx.check(raw_loader(shape, dtype, offset), data, name="v.raw", tag="raw")
    # MetaImage: header with the .raw beside it
    raw_path = ctx.tmp("case/v.raw")
    raw_path.write_bytes(raw)
    for field, values in MHD_FIELDS.items():
        for v in values:
            ctx.check(load, _mhd_variant(s["v.mhd"], field, v), name="v.mhd", tag="mhd-field", note=f"{field}={v}")
            mha = _mhd_variant(s["v.mha"].split(b"ElementDataFile = LOCAL\n")[0] + b"ElementDataFile = LOCAL\n", field, v)
            if field != "ElementDataFile":
                ctx.check(load, mha + raw, name="v.mha", tag="mha-field", note=f"{field}={v}")
    for cut in (0, 1, 100, len(raw) - 1):
        raw_path.write_bytes(raw[:cut])
        ctx.check(load, s["v.mhd"], name="v.mhd", tag="mhd-short-raw")
    raw_path.write_bytes(raw)
    # compressed MetaImage: a zlib bomb behind a small DimSize, and garbage
    bomb = zlib.compress(bytes(64 * 2**20), 9)
    raw_path.write_bytes(bomb)
    for dims in ("16 16 3", "4096 4096 4"):
        hdr = _mhd_variant(_mhd_variant(s["v.mhd"], "CompressedData", "True"), "DimSize", dims)
        ctx.check(load, hdr, name="v.mhd", tag="mhd-bomb", mem_budget=4 * 64 * 2**20 * 2)
    raw_path.write_bytes(b"garbage" * 10)
    ctx.check(load, _mhd_variant(s["v.mhd"], "CompressedData", "True"), name="v.mhd", tag="mhd-bomb")
    raw_path.write_bytes(raw)
    standard_campaign(ctx, load, s["v.mha"], name="v.mha", tag="mha", flips_every=16, trunc_limit=100)
    # NIfTI / NRRD volumes through load()
    for name in ("v.nii.gz", "v.nrrd"):
        standard_campaign(ctx, load, s[name], name=name, tag=name.split(".")[1], flips_every=6, trunc_limit=100)


@pytest.mark.slow
def test_fuzz_stacks_raw_mhd():
    import pytest

    if not HAVE_LOADERS:
        pytest.skip("ctui.engine.io.series not available yet")
    res = run_campaign("test_fuzz_stacks", "campaign", examples=fuzz_examples(60))
    assert_clean("stacks/raw/mhd/nifti/nrrd", res, min_cases=2000)
