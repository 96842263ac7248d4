"""Issue 41's hostile families for the command fuzzer (tests/fuzz/fuzz_cli.py), round four.

* ``deflate``: a 16-slice Deflated Explicit VR Little Endian series; one slice replaced by a
  deflate bomb (megabytes of zeros behind a 48x48 header), cut, bit-flipped in its stream, or
  given a larger Rows/Columns claim;
* ``jpeg-ls``: the same series in JPEG-LS; one frame truncated, flipped, given another size
  in its SOF-55 segment, or replaced by garbage (CharLS took 5-13 s to fail on each);
* ``enhanced``: an Enhanced CT multi-frame file whose per-frame positions (NaN, two values,
  1e308, duplicates) or shared orientation vectors (zero, non-unit, non-orthogonal, NaN)
  are hostile; exit 0 on ``mesh --json`` must say the repaired orientation (rule ``wrong``);
* ``fifo-source``: a project whose source series is a FIFO, a link to /dev/null, a dangling
  link or a folder link, through export/measure/render (a blocking read is rule ``slow``);
* ``c1-names``: a series folder whose name holds C1 bytes and escapes, shown with
  ``--keep-identifiers`` (rule ``control``, raw bytes included);
* ``limits``: descriptors (RLIMIT_NOFILE 12-32), file size (RLIMIT_FSIZE) and closed standard
  streams around ``info``/``mesh``/``segment``;
* ``temp-races``: the output's folder holds the user's own ``.o.stl.keep.tmp``, a symlink
  named like ctui's temp and a dead temp of ctui's; the user's files must survive.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

KINDS4 = ("deflate", "jpeg-ls", "enhanced", "fifo-source", "c1-names", "limits", "temp-races")
C1_NAME = b"ser\x9b2J\x1b]0;t\x07\x85".decode("utf-8", "surrogateescape")


def _series_files(series: Path, sub: str, syntax: str | None) -> dict[str, bytes]:
    import pydicom

    out = {}
    for f in sorted(series.glob("*.dcm")):
        if syntax is None:
            out[f"{sub}/{f.name}"] = f.read_bytes()
            continue
        ds = pydicom.dcmread(f)
        if syntax == "jpeg-ls":
            ds.compress(pydicom.uid.JPEGLSLossless)
        else:
            ds.file_meta.TransferSyntaxUID = pydicom.uid.DeflatedExplicitVRLittleEndian
        buf = io.BytesIO()
        ds.save_as(buf, enforce_file_format=True)
        out[f"{sub}/{f.name}"] = buf.getvalue()
    return out


def _enhanced_file(work: Path) -> bytes:
    import pydicom
    from test_load_synthetic import _enhanced

    from ctui.engine.core.volume import Volume

    data = np.full((9, 32, 32), -1000, np.int16)
    data[2:7, 8:24, 8:24] = 300
    p = _enhanced(work, Volume(data=data, spacing=(2.0, 1.0, 1.0), modality="CT", window=(40, 400)), list(range(9)),
                  name="enhanced-seed.dcm")
    ds = pydicom.dcmread(p)
    ds.StudyInstanceUID, ds.FrameOfReferenceUID = pydicom.uid.generate_uid(), pydicom.uid.generate_uid()
    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    return buf.getvalue()


def _project_with_source(project: bytes, source: str) -> bytes:
    with zipfile.ZipFile(io.BytesIO(project)) as zi:
        members = {n: zi.read(n) for n in zi.namelist()}
    meta = json.loads(members["project.json"])
    meta["source_path"] = source
    members["project.json"] = json.dumps(meta).encode()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zo:
        for n, b in members.items():
            zo.writestr(n, b)
    return buf.getvalue()


def family_seeds4(seed_cls: Any, work: Path, base: dict[str, bytes], series: Path) -> list:
    """The round-four seeds (``base``: p.ctui); the case folder is ``work.parent / "case"``."""
    out = []
    case = work.parent / "case"
    mesh = ["mesh", "{dir}/S", "--iso", "100", "--out", "{dir}/o.stl", "--json"]
    for kind, sub, syntax in (("deflate", "d", "deflate"), ("jpeg-ls", "j", "jpeg-ls")):
        try:
            files = _series_files(series, sub, syntax)
        except Exception:  # noqa: BLE001 - no JPEG-LS encoder here: the family is left out
            continue
        for argv in (["info", "{dir}/S", "--json"], mesh):
            out.append(seed_cls(f"{kind}-{argv[0]}", kind, f"{sub}/slice005.dcm", files,
                                [a.replace("S", sub) if a == "{dir}/S" else a for a in argv]))
    enh = {"e/mf.dcm": _enhanced_file(work)}
    for argv in (["info", "{dir}/e", "--json"], ["mesh", "{dir}/e", "--iso", "100", "--out", "{dir}/o.stl", "--json"]):
        out.append(seed_cls(f"enhanced-{argv[0]}", "enhanced", "e/mf.dcm", enh, argv))
    proj = _project_with_source(base["p.ctui"], str(case / "src"))
    for argv in (["export", "{dir}/p.ctui", "--format", "dicom-seg", "--out", "{dir}/x.dcm"],
                 ["measure", "{dir}/p.ctui", "--values"], ["render", "{dir}/p.ctui", "--out", "{dir}/r.png",
                                                           "--size", "32x32", "--mode", "dvr"]):
        out.append(seed_cls(f"fifo-source-{argv[0]}", "fifo-source", "p.ctui", {"p.ctui": proj}, argv,
                            specials={"src": "fifo"}))
    c1 = {f"{C1_NAME}/{k.split('/')[1]}": v for k, v in _series_files(series, "x", None).items()}
    for argv in (["info", "{dir}/" + C1_NAME, "--keep-identifiers"],
                 ["mesh", "{dir}/" + C1_NAME, "--iso", "100", "--out", "{dir}/o.stl", "--keep-identifiers"],
                 ["segment", "{dir}/" + C1_NAME, "--seed", "24,24,8", "--range", "200:400", "--keep-identifiers"]):
        out.append(seed_cls(f"c1-names-{argv[0]}", "c1-names", next(iter(c1)), c1, argv))
    plain = _series_files(series, "s", None)
    for argv in (["info", "{dir}/s", "--json"], ["mesh", "{dir}/s", "--iso", "100", "--out", "{dir}/o.stl", "--json"],
                 ["segment", "{dir}/s", "--seed", "24,24,8", "--range", "200:400", "--mask", "{dir}/m.nii.gz"]):
        out.append(seed_cls(f"limits-{argv[0]}", "limits", "s/slice005.dcm", plain, argv))
    out.append(seed_cls("temp-races", "temp-races", "p.ctui", {"p.ctui": base["p.ctui"]},
                        ["mesh", "{dir}/p.ctui", "--out", "{dir}/o.stl", "--json"],
                        specials={".o.stl.keep.tmp": "user-file", ".o.stl.zz9zz9zz.tmp.stl": "user-link",
                                  ".o.stl.ab12cd34.tmp.stl": "dead-temp"}))
    return out


LIMITS = [{"NOFILE": 12}, {"NOFILE": 16}, {"NOFILE": 20}, {"NOFILE": 32}, {"FSIZE": 1000}, {"FSIZE": 100_000},
          {"close": 0}, {"close": 1}, {"close": 2}, {"close": 0, "NOFILE": 20}]
POSITIONS = [[0.0, float("nan"), 8.0], [0.0, 8.0], [1e308, 0.0, 0.0], [0.0, 0.0, 0.0], [float("inf"), 0, 0]]
ORIENTATIONS = [[0, 0, 0, 0, 0, 0], [2, 0, 0, 0, 2, 0], [1, 0, 0, 0.3, 1, 0], [1, 0, 0, 1, 0, 0],
                [float("nan"), 0, 0, 0, 1, 0], [0, 1, 0, 1, 0, 0], [1, 0, 0, 0, 1e-9, 0]]


def mutate_family4(seed: Any, rng) -> tuple[Any, bytes, str]:
    """(seed, data, mutator) for a round-four family seed."""
    data = seed.files[seed.main]
    kind = seed.kind
    if kind == "limits":
        lim = LIMITS[int(rng.integers(0, len(LIMITS)))]
        return replace(seed, limits=lim), data, f"limits={lim}"
    if kind == "fifo-source":
        what = ("fifo", "devnull-link", "dangling-link", "dir-link")[int(rng.integers(0, 4))]
        return replace(seed, specials={"src": what}), data, f"source={what}"
    if kind in ("c1-names", "temp-races"):
        return seed, data, kind
    try:
        if kind == "deflate":
            return seed, _deflate_mutate(data, rng), "deflate"
        if kind == "jpeg-ls":
            return seed, _jpeg_ls_mutate(data, rng), "jpeg-ls"
        return seed, _enhanced_mutate(data, rng), "enhanced"
    except Exception:  # noqa: BLE001 - pydicom refused the edit: a byte flip instead
        b = bytearray(data)
        b[int(rng.integers(0, len(b)))] ^= 0xFF
        return seed, bytes(b), f"{kind}-flip"


def _save(ds: Any) -> bytes:
    buf = io.BytesIO()
    ds.save_as(buf, enforce_file_format=True)
    return buf.getvalue()


def _deflate_mutate(data: bytes, rng) -> bytes:
    import pydicom

    r = rng.random()
    if r < 0.3:  # a bomb: zeros behind the 48x48 header, deflated
        ds = pydicom.dcmread(io.BytesIO(data))
        ds.PixelData = b"\0" * int(rng.integers(1, 256) << 20)
        return _save(ds)
    if r < 0.55:
        return data[: int(rng.integers(200, len(data)))]
    if r < 0.8:
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 6))):
            b[int(rng.integers(300, len(b)))] ^= int(rng.integers(1, 256))
        return bytes(b)
    ds = pydicom.dcmread(io.BytesIO(data))
    ds.Rows, ds.Columns = int(rng.choice([49, 512, 4096, 65535])), int(rng.choice([48, 512, 65535]))
    return _save(ds)


def _jpeg_ls_mutate(data: bytes, rng) -> bytes:
    import pydicom
    from pydicom.encaps import encapsulate, generate_frames

    ds = pydicom.dcmread(io.BytesIO(data))
    fr = bytearray(next(generate_frames(ds.PixelData, number_of_frames=1)))
    r = rng.random()
    if r < 0.4:
        fr = fr[: int(rng.integers(2, len(fr)))]
    elif r < 0.7:
        for _ in range(int(rng.integers(1, 5))):
            fr[int(rng.integers(2, len(fr) - 2))] ^= int(rng.integers(1, 256))
    elif r < 0.85:
        i = fr.find(b"\xff\xf7")
        fr[i + 5:i + 9] = int(rng.integers(0, 65536)).to_bytes(2, "big") + int(rng.integers(0, 65536)).to_bytes(2, "big")
    else:
        fr = bytearray(b"\xff\xd8\xff\xf7" + bytes(rng.integers(0, 256, int(rng.integers(8, 600)), dtype=np.uint8)))
    ds.PixelData = encapsulate([bytes(fr)])
    return _save(ds)


def _enhanced_mutate(data: bytes, rng) -> bytes:
    import pydicom
    from pydicom import config

    ds = pydicom.dcmread(io.BytesIO(data))
    per = ds.PerFrameFunctionalGroupsSequence
    old = config.settings.writing_validation_mode
    config.settings.writing_validation_mode = config.IGNORE
    try:
        if rng.random() < 0.5:
            for _ in range(int(rng.integers(1, 4))):
                k = int(rng.integers(0, len(per)))
                per[k].PlanePositionSequence[0].ImagePositionPatient = POSITIONS[int(rng.integers(0, len(POSITIONS)))]
        else:
            iop = ORIENTATIONS[int(rng.integers(0, len(ORIENTATIONS)))]
            ds.SharedFunctionalGroupsSequence[0].PlaneOrientationSequence[0].ImageOrientationPatient = iop
        return _save(ds)
    finally:
        config.settings.writing_validation_mode = old


def oracle4(seed: Any, rep: dict, data: bytes) -> str | None:
    """An enhanced file with an invalid orientation meshed with exit 0 must say the assumption."""
    if seed.kind != "enhanced" or seed.argv[0] != "mesh":
        return None
    import pydicom

    try:
        from ctui.engine.io.dicomrefs import orientation_fault

        ds = pydicom.dcmread(io.BytesIO(data))
        iop = ds.SharedFunctionalGroupsSequence[0].PlaneOrientationSequence[0].ImageOrientationPatient
    except Exception:  # noqa: BLE001
        return None
    if orientation_fault(iop) and not any("assumed (orientation)" in n for n in rep.get("notes") or []):
        return f"exit 0 on an invalid ImageOrientationPatient {list(iop)} without an orientation assumption"
    return None
