"""Issue 26's hostile families for the command fuzzer (tests/fuzz/fuzz_cli.py).

What an outside campaign broke that byte mutations of ctui's own files do not reach:

* ``outputs``: the command's output is a FIFO, ``/dev/null`` or a symlink to a device
  (``--plot``, ``--csv``, ``--out``, ``--mask``): the node must survive (rule ``replaced``);
* ``options``: numeric options drawn from nan, inf, 1e308, 0, huge counts (``--iso``,
  ``--neck``, ``--filter clahe:tiles=0``, ``--azimuth``, ``--fps``, ``--step``, ``--path``...);
* ``nrrd-detached``: .nhdr / .nrrd headers whose data is ``/dev/zero``, a FIFO, a gzip bomb,
  ``line skip`` beyond the file, ascii/hex payloads;
* ``dicom-fields``: a DICOM slice with one header field set by pydicom to a hostile value
  (NumberOfFrames, RescaleSlope 1e-300, PixelSpacing 1e-30, MONOCHROME1, a compressed
  transfer syntax over raw bytes, Float Pixel Data with NaN, SeriesDescription with
  terminal escapes), run through ``ctui info`` as text (rule ``control``);
* ``seg-frames``: the dcmqi liver DICOM-SEG with NumberOfFrames / functional groups changed;
* ``nifti-types``: complex64, RGB24, negative pixdim, sheared sform, NaN voxels through
  ``info``, ``mesh --iso`` and ``render``-free commands;
* ``batch``: manifests in Latin-1/UTF-16, with huge fields, formula names, device paths;
* ``mesh-degenerate``: meshes whose triangles have no area.

Each family is a list of :class:`fuzz_cli.Seed`-like cases built by :func:`family_seeds`;
:func:`mutate_family` draws one case; :func:`layout_specials` makes the FIFOs and links a
case needs and :func:`specials_intact` checks them afterwards. :func:`control_chars`
finds a control character in what reached the terminal.
"""

from __future__ import annotations

import gzip
import io
import os
import re
import struct
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ESCAPES = ["\x1b]52;c;ZXZpbA==\x07", "\x1b[2J", "\x1b[31mred", "\x9b31m", "\u202eevil", "a\rb", "\x00nul", "\x07bell"]
NUMBERS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "0", "-0", "-1", "1e-300", "100000", "1000000",
           "2147483648", "1e21", "0.5", "3"]
# (family argv template, option, value kinds); {v} is the hostile value
OPTION_CASES = [
    ["mesh", "{series}", "--iso", "{v}", "--out", "{dir}/o.stl", "--json"],
    ["mesh", "{dir}/p.ctui", "--smooth", "{v}", "--out", "{dir}/o.stl", "--json"],
    ["mesh", "{dir}/p.ctui", "--decimate", "{v}", "--out", "{dir}/o.stl", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--neck", "{v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--neighbourhood", "{v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "{v}:400", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--tolerance", "{v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--leak-factor", "{v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--min-area", "{v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "clahe:tiles={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "gaussian:sigma={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "erode:iterations={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "opening:size={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "median:size={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--filter", "sharpen:amount={v}", "--json"],
    ["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--window", "{v},{v}", "--json"],
    ["measure", "{dir}/p.ctui", "--path", "auto", "--step", "{v}", "--json"],
    ["measure", "{dir}/p.ctui", "--path", "{v},0,0;0,0,{v}", "--json"],
    ["measure", "{dir}/p.ctui", "--path", "auto", "--between", "{v},{v}", "--json"],
    ["measure", "{dir}/p.ctui", "--path", "auto", "--average", "{v}", "--json"],
    ["measure", "{dir}/p.ctui", "--object", "{v}", "--json"],
    ["drift", "{dir}/p.ctui", "--threshold", "{v}", "--json"],
    ["drift", "{dir}/p.ctui", "--fit-window", "{v}", "--json"],
    ["info", "{series}", "--spacing", "{v}", "--json"],
    ["info", "{series}", "--crop", "0,{v},,,,", "--json"],
    ["info", "{series}", "--downsample", "{v}", "--json"],
    ["export", "{dir}/p.ctui", "--format", "csv", "--object", "{v}", "--out", "{dir}/o.csv", "--json"],
]
# outputs that must never replace a non-regular file: (argv, the output's name)
OUTPUT_CASES = [
    (["drift", "{dir}/p.ctui", "--plot", "{dir}/out.png"], "out.png"),
    (["measure", "{dir}/p.ctui", "--path", "auto", "--csv", "{dir}/out.csv"], "out.csv"),
    (["measure", "{dir}/p.ctui", "--path", "auto", "--plot", "{dir}/out.png"], "out.png"),
    (["mesh", "{dir}/p.ctui", "--out", "{dir}/out.stl"], "out.stl"),
    (["export", "{dir}/p.ctui", "--format", "csv", "--out", "{dir}/out.csv"], "out.csv"),
    (["export", "{dir}/p.ctui", "--format", "nifti", "--out", "{dir}/out.nii.gz"], "out.nii.gz"),
    (["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--mask", "{dir}/out.nii.gz"], "out.nii.gz"),
    (["segment", "{series}", "--seed", "24,24,8", "--range", "200:400", "--project", "{dir}/out.ctui"], "out.ctui"),
]
# (never /dev/null itself: a regression would replace this machine's /dev/null, as root)
SPECIALS = ("fifo", "devnull-link", "dangling-link", "dir-link", "file-link")  # file-link: written through, kept


def _nrrd_cases(vals: bytes) -> dict[str, bytes]:
    hdr = ("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 8 12\nspace: left-posterior-superior\n"
           "space directions: (1,0,0) (0,1,0) (0,0,2)\n")
    return {
        "g.nrrd": (hdr + "encoding: gzip\n\n").encode() + gzip.compress(vals),
        "a.nrrd": (hdr + "encoding: ascii\n\n").encode() + " ".join(map(str, vals)).encode(),
        "h.nrrd": (hdr + "encoding: hex\n\n").encode() + vals.hex().encode(),
        "l.nrrd": (hdr + "encoding: raw\nline skip: 2\n\n").encode() + b"x\ny\n" + vals,
        "d.nhdr": (hdr + "encoding: raw\ndata file: d.raw\n\n").encode(),
        "z.nhdr": (hdr + "encoding: gzip\ndata file: d.raw.gz\n\n").encode(),
    }


def family_seeds(seed_cls: Any, work: Path, base: dict[str, bytes], series: Path) -> list:
    """The family seeds: ``base`` holds ctui's own files (p.ctui, m.nii, s.dcm, b.stl)."""
    out = []
    vals = (np.arange(960) * 7 % 256).astype(np.uint8).tobytes()
    extra = {"d.raw": vals, "d.raw.gz": gzip.compress(vals)}
    for name, data in _nrrd_cases(vals).items():
        out.append(seed_cls(f"nrrd-detached-{name}", "nrrd-detached", name, {name: data, **extra},
                            ["info", "{dir}/" + name, "--json"]))
    out.append(seed_cls("dicom-fields", "dicom-fields", "s.dcm", {"s.dcm": base["s.dcm"]}, ["info", "{dir}/s.dcm"]))
    out.append(seed_cls("dicom-fields-json", "dicom-fields", "s.dcm", {"s.dcm": base["s.dcm"]},
                        ["info", "{dir}/s.dcm", "--json"]))
    liver = Path(os.environ.get("CTUI_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
    liver = liver / "dcmqi_seg" / "liver.dcm"
    if liver.is_file():
        out.append(seed_cls("seg-frames", "seg-frames", "seg.dcm", {"seg.dcm": liver.read_bytes()},
                            ["measure", "{dir}/seg.dcm", "--json", "--no-mesh"], real=True))
    for argv in (["info", "{dir}/v.nii", "--json"], ["mesh", "{dir}/v.nii", "--iso", "50", "--out", "{dir}/o.stl",
                                                      "--json"]):
        out.append(seed_cls(f"nifti-types-{argv[0]}", "nifti-types", "v.nii", {"v.nii": _nifti_seed()}, argv))
    out.append(seed_cls("mesh-degenerate", "mesh-degenerate", "b.stl", {"b.stl": base["b.stl"]},
                        ["measure", "{dir}/b.stl", "--json"]))
    manifest = f'series,seed,range,name\n{series},"24,24,8",200:400,kidney\n'.encode()
    out.append(seed_cls("batch", "batch", "m.csv", {"m.csv": manifest},
                        ["batch", "{dir}/m.csv", "--out", "{dir}/r.csv", "--threads", "--workers", "1", "--json"]))
    for i, (argv, target) in enumerate(OUTPUT_CASES):
        out.append(seed_cls(f"outputs-{i}", "outputs", "p.ctui", {"p.ctui": base["p.ctui"]},
                            [a.replace("{series}", str(series)) for a in argv], specials={target: "fifo"}))
    for i, argv in enumerate(OPTION_CASES):
        out.append(seed_cls(f"options-{i}", "options", "p.ctui", {"p.ctui": base["p.ctui"]},
                            [a.replace("{series}", str(series)) for a in argv]))
    return out


def _nifti_seed() -> bytes:
    import nibabel as nib

    a = np.zeros((14, 12, 10), np.float32)
    a[3:10, 3:9, 2:8] = 100
    img = nib.Nifti1Image(a, np.diag([1.0, 1.0, 2.0, 1.0]))
    return img.to_bytes()


def mutate_family(seed: Any, rng) -> tuple[Any, bytes, str]:
    """(seed, possibly with a hostile argv or specials, data, mutator name) for a family seed."""
    data = seed.files[seed.main]
    kind = seed.kind
    if kind == "options":
        v = NUMBERS[int(rng.integers(0, len(NUMBERS)))]
        return replace(seed, argv=[a.replace("{v}", v) for a in seed.argv]), data, f"option={v}"
    if kind == "outputs":
        what = SPECIALS[int(rng.integers(0, len(SPECIALS)))]
        return replace(seed, specials={k: what for k in seed.specials}), data, f"output={what}"
    if kind == "nrrd-detached":
        return seed, _nrrd_mutate(data, rng), "nrrd-detached"
    if kind == "dicom-fields":
        return seed, _dicom_mutate(data, rng), "dicom-field"
    if kind == "seg-frames":
        return seed, _seg_mutate(data, rng), "seg-frames"
    if kind == "nifti-types":
        return seed, _nifti_mutate(data, rng), "nifti-types"
    if kind == "mesh-degenerate":
        return seed, _collapse_stl(data, rng), "mesh-degenerate"
    if kind == "batch":
        return seed, _batch_mutate(data, rng), "batch-manifest"
    return seed, data, "unchanged"


NRRD_LINES = ["data file: /dev/zero", "data file: /dev/urandom", "data file: fifo", "data file: .", "data file: /proc/self/fd/0",
              "line skip: 99999999", "line skip: -1", "byte skip: -1", "byte skip: 99999999", "encoding: gzip",
              "encoding: bzip2", "encoding: ascii", "encoding: hex", "encoding: raw", "encoding: zstd",
              "sizes: 100000 100000 100000", "sizes: 10 8 99999", "type: double", "type: complex"]


def _nrrd_mutate(data: bytes, rng) -> bytes:
    i = data.find(b"\n\n")
    head, rest = (data[: i + 1], data[i + 1:]) if i >= 0 else (data, b"")
    lines = head.decode("latin-1").rstrip("\n").split("\n")
    for _ in range(int(rng.integers(1, 3))):
        new = NRRD_LINES[int(rng.integers(0, len(NRRD_LINES)))]
        key = new.split(":")[0]
        lines = [ln for ln in lines if not ln.startswith(key + ":")]
        lines.insert(int(rng.integers(1, len(lines) + 1)), new)
    r = rng.random()
    if r < 0.3 and rest:  # a gzip payload that inflates far past the declared size
        rest = b"\n" + gzip.compress(bytes(int(rng.integers(1, 50)) * 1_000_000))
    elif r < 0.4:
        rest = rest[: int(rng.integers(0, len(rest) + 1))]
    return ("\n".join(lines) + "\n").encode("latin-1") + rest


DICOM_FIELDS = {
    "NumberOfFrames": ["2147483647", "0", "-1", "46", "abc"],
    "RescaleSlope": ["1e-300", "1e300", "0", "nan", "-1", "1e7"],
    "RescaleIntercept": ["1e300", "nan", "-1e8"],
    "PixelSpacing": [["1e-30", "1e-30"], ["0", "0"], ["nan", "1"], ["1e30", "1"], ["-1", "-1"]],
    "PhotometricInterpretation": ["MONOCHROME1", "RGB", "YBR_FULL", "PALETTE COLOR", ""],
    "Rows": [0, 1, 65535], "Columns": [0, 1, 65535], "BitsAllocated": [1, 8, 32, 64], "BitsStored": [0, 1, 33],
    "SamplesPerPixel": [0, 3, 4], "PixelRepresentation": [1, 2],
    "SliceThickness": ["1e-30", "nan", "0"], "ImagePositionPatient": [["1e308", "0", "0"], ["nan", "0", "0"]],
    "ImageOrientationPatient": [["1", "5", "0", "0", "1", "0"], ["0", "0", "0", "0", "0", "0"]],
}
SYNTAXES = ["1.2.840.10008.1.2.5", "1.2.840.10008.1.2.4.50", "1.2.840.10008.1.2.4.90", "1.2.840.10008.1.2.4.80",
            "1.2.840.10008.1.2.2"]


def _dicom_mutate(data: bytes, rng) -> bytes:
    import pydicom
    from pydicom.encaps import encapsulate

    try:
        ds = pydicom.dcmread(io.BytesIO(data), force=True)
        r = rng.random()
        if r < 0.2:
            ds.SeriesDescription = "".join(ESCAPES[int(rng.integers(0, len(ESCAPES)))] for _ in range(2))
            if rng.random() < 0.5:
                ds.PatientName = ESCAPES[int(rng.integers(0, len(ESCAPES)))]
        elif r < 0.35:  # a compressed syntax over garbage fragments (or a real frame cut short)
            ds.file_meta.TransferSyntaxUID = SYNTAXES[int(rng.integers(0, len(SYNTAXES)))]
            raw = bytes(ds.PixelData)
            frag = raw[: int(rng.integers(1, len(raw)))] if rng.random() < 0.5 else os.urandom(int(rng.integers(8, 900)))
            ds.PixelData = encapsulate([frag])
            ds["PixelData"].VR = "OB"
        elif r < 0.45:  # Float Pixel Data with NaN and inf
            arr = np.asarray(ds.pixel_array, np.float32)
            arr.flat[:: int(rng.integers(2, 50))] = np.nan
            arr.flat[1] = np.inf
            del ds.PixelData
            ds.FloatPixelData = arr.tobytes()
            ds.BitsAllocated = 32
            for k in ("BitsStored", "HighBit", "PixelRepresentation", "RescaleSlope", "RescaleIntercept"):
                if k in ds:
                    delattr(ds, k)
        else:
            for _ in range(int(rng.integers(1, 3))):
                key = list(DICOM_FIELDS)[int(rng.integers(0, len(DICOM_FIELDS)))]
                vals = DICOM_FIELDS[key]
                setattr(ds, key, vals[int(rng.integers(0, len(vals)))])
        buf = io.BytesIO()
        ds.save_as(buf, enforce_file_format=False)
        return buf.getvalue()
    except Exception:  # noqa: BLE001 - pydicom refused the edit: a plain byte flip instead
        b = bytearray(data)
        b[int(rng.integers(0, len(b)))] ^= 0xFF
        return bytes(b)


def _seg_mutate(data: bytes, rng) -> bytes:
    import pydicom

    ds = pydicom.dcmread(io.BytesIO(data))
    r = rng.random()
    if r < 0.5:
        ds.NumberOfFrames = [1, 2, 2**31 - 1, 2**16, 0, 4][int(rng.integers(0, 6))]
    elif r < 0.7:
        ds.PerFrameFunctionalGroupsSequence = ds.PerFrameFunctionalGroupsSequence[: int(rng.integers(0, 3))]
    elif r < 0.85:
        ds.PixelData = bytes(ds.PixelData)[: int(rng.integers(0, len(ds.PixelData)))]
    else:
        ds.SegmentSequence[0].SegmentLabel = ESCAPES[int(rng.integers(0, len(ESCAPES)))][:60]
    buf = io.BytesIO()
    ds.save_as(buf)
    return buf.getvalue()


NIFTI_TYPES = [(32, 8), (1792, 16), (128, 3), (2304, 4), (16, 4), (2, 1), (512, 2), (1024, 8), (1536, 16)]


def _nifti_mutate(data: bytes, rng) -> bytes:
    b = bytearray(data)
    r = rng.random()
    if r < 0.35:  # datatype / bitpix: complex, RGB, RGBA, float128...
        code, size = NIFTI_TYPES[int(rng.integers(0, len(NIFTI_TYPES)))]
        struct.pack_into("<hh", b, 70, code, size * 8)
    elif r < 0.55:  # negative or tiny pixdim
        struct.pack_into("<f", b, 80 + 4 * int(rng.integers(0, 3)), [-2.0, -1e-30, 1e-30, 0.0][int(rng.integers(0, 4))])
    elif r < 0.75:  # a sheared sform (code 1)
        struct.pack_into("<h", b, 254, 1)
        struct.pack_into("<4f", b, 280, 1.0, float(rng.choice([0.5, 5.0, 1e6])), 0.0, 0.0)
    elif r < 0.9:  # NaN / inf voxels
        off = int(struct.unpack_from("<f", b, 108)[0])
        for _ in range(5):
            i = off + 4 * int(rng.integers(0, (len(b) - off) // 4))
            struct.pack_into("<f", b, i, float(rng.choice([np.nan, np.inf, -np.inf])))
    else:  # vox_offset 0: the header read as voxels
        struct.pack_into("<f", b, 108, 0.0)
    return bytes(b)


def _collapse_stl(data: bytes, rng) -> bytes:
    b = bytearray(data)
    n = struct.unpack_from("<I", b, 80)[0]
    share = rng.random()
    for i in range(n):
        if rng.random() < share:
            off = 84 + 50 * i + 12
            v = struct.unpack_from("<3f", b, off)
            struct.pack_into("<6f", b, off + 12, *v, *v)
    if rng.random() < 0.2:
        b = b[:80] + struct.pack("<I", 0)
    return bytes(b)


def _batch_mutate(data: bytes, rng) -> bytes:
    text = data.decode()
    r = rng.random()
    if r < 0.2:
        return text.encode(["latin-1", "utf-16", "utf-16-be", "utf-8-sig"][int(rng.integers(0, 4))], "replace")
    if r < 0.35:
        return text.replace("kidney", "x" * 140_000).encode()
    if r < 0.55:
        return text.replace("kidney", ["=HYPERLINK(\"http://x\")", "@SUM(A1)", "+1+2", "-2-3", "\x1b[2Jname"][
            int(rng.integers(0, 5))]).encode()
    if r < 0.7:
        return text.replace(text.split("\n")[1].split(",")[0], ["/dev/zero", "/dev/null", "/proc/self/fd/0", "."][
            int(rng.integers(0, 4))]).encode()
    if r < 0.85:
        return os.urandom(int(rng.integers(1, 400)))
    lines = text.split("\n")
    return "\n".join(lines[:1] + lines[1:2] * int(rng.integers(1, 30))).encode()


# --------------------------------------------------------------------- special outputs
def layout_specials(case_dir: Path, specials: dict[str, str]) -> None:
    """Make each special output node the case needs (a FIFO, /dev/null links...)."""
    for name, what in specials.items():
        p = case_dir / name
        if what == "fifo":
            os.mkfifo(p)
        elif what == "devnull-link":
            p.symlink_to("/dev/null")
        elif what == "dir-link":
            p.symlink_to(case_dir)
        elif what == "file-link":
            (case_dir / f"target-{name}").write_bytes(b"old")
            p.symlink_to(case_dir / f"target-{name}")
        elif what == "dangling-link":
            p.symlink_to(case_dir / "nowhere" / "x")
        elif what == "user-file":  # a user's file named like a temp: must survive (issue 41)
            p.write_bytes(b"mine")
        elif what == "user-link":
            (case_dir / "victim").write_bytes(b"precious")
            p.symlink_to(case_dir / "victim")
        elif what == "dead-temp":
            p.write_bytes(b"left by a killed writer")
            os.utime(p, (1, 1))


def specials_intact(case_dir: Path, specials: dict[str, str]) -> str | None:
    """None when every special node is as it was (and /dev/null is still a device)."""
    import stat

    if not stat.S_ISCHR(os.stat("/dev/null").st_mode):
        return "/dev/null is no longer a character device"
    for name, what in specials.items():
        p = case_dir / name
        if what == "dead-temp":  # ctui's own dead temp: removing it is right
            continue
        try:
            st = os.lstat(p)
        except OSError:
            return f"{name} ({what}) was removed"
        if what == "user-file":
            if p.read_bytes() != b"mine":
                return f"{name}: the user's file was changed"
            continue
        if what == "user-link" and (case_dir / "victim").read_bytes() != b"precious":
            return f"{name}: the symlink's target was overwritten"
        if what == "fifo" and not stat.S_ISFIFO(st.st_mode):
            return f"{name}: the FIFO was replaced by a regular file"
        if what != "fifo" and not stat.S_ISLNK(st.st_mode):
            return f"{name}: the symbolic link ({what}) was replaced by a regular file"
    return None


_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\udc80-\udc9f]")  # + raw C1 bytes


def control_chars(text: str) -> str | None:
    """The first control character (other than newline and tab) in terminal output, or None."""
    m = _CONTROL.search(text)
    return None if m is None else f"{m.group(0)!r} at {m.start()}: {text[max(0, m.start() - 40):m.start() + 20]!r}"
