"""Run the permanent regression corpus (tests/fuzz/regression_corpus, see its README) through
the readers under the fuzz harness rules, plus generated cases that cannot be stored
as files (deep folder trees, symlink loops)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from test_fuzz_harness import CORPUS, assert_clean, run_campaign


def warm_up() -> None:
    import ctui.engine.io.labels  # noqa: F401
    import ctui.engine.io.mric  # noqa: F401
    import ctui.engine.io.project  # noqa: F401

    try:
        import ctui.engine.io.series  # noqa: F401
    except ImportError:
        pass
    import nibabel  # noqa: F401
    import nrrd  # noqa: F401
    import pydicom  # noqa: F401


def _readers():
    from ctui.engine.io.labels import load_labels
    from ctui.engine.io.mric import read_mric
    from ctui.engine.io.project import load_project

    r = {"mric": read_mric, "labels": load_labels, "project": load_project}
    try:
        from ctui.engine.io.series import load

        r.update(dicom=load, mhd=load, stacks=load)
    except ImportError:
        pass
    try:
        from ctui.engine.io.meshes import load_mesh

        r["mesh"] = load_mesh
    except ImportError:
        pass
    return r


def campaign(ctx) -> None:
    readers = _readers()
    for kind in sorted(p.name for p in CORPUS.iterdir() if p.is_dir()):
        reader = readers.get(kind)
        if reader is None:
            continue
        for f in sorted(CORPUS.joinpath(kind).rglob("*")):
            if not f.is_file() or (kind == "mhd" and f.suffix.lower() not in (".mhd", ".mha")):
                continue
            ctx.check(reader, f, tag=f"corpus-{kind}", note=f.name)
        if kind == "dicom":  # each broken file inside an otherwise valid series
            from test_fuzz_dicom import write_series

            for f in sorted(CORPUS.joinpath(kind).glob("*.dcm")):
                d = ctx.tmp(f"series-{f.stem}/x").parent
                write_series(d)
                shutil.copy(f, d / "im1.dcm")
                ctx.check(readers["dicom"], d, tag="corpus-dicom-in-series", note=f.name)
    if "dicom" in readers:
        from test_fuzz_dicom import write_series

        root = ctx.tmp("gen/x").parent
        deep = str(root / "deep")
        p = deep
        os.mkdir(p)
        for _ in range(1100):
            p += "/d"
            os.mkdir(p)
        from test_fuzz_dicom import dicom_bytes, make_slice

        for i in range(2):  # plain string paths: pathlib recurses on 1100 parts
            with open(f"{p}/im{i}.dcm", "wb") as fh:
                fh.write(dicom_bytes(make_slice(i)))
        ctx.check(readers["dicom"], Path(deep), tag="corpus-generated", note="1100 nested folders")
        loop = root / "loop"
        write_series(loop)
        os.symlink("..", loop / "up")
        os.symlink(".", loop / "here")
        os.symlink("loopfile.dcm", loop / "loopfile.dcm")
        ctx.check(readers["dicom"], loop, tag="corpus-generated", note="symlink loops")


def test_regression_corpus():
    n_files = sum(1 for f in CORPUS.rglob("*") if f.is_file() and f.name != "README.md")
    assert n_files >= 6
    res = run_campaign("test_fuzz_corpus", "campaign", examples=1)
    assert_clean("regression corpus", res, min_cases=min(n_files, 6))
