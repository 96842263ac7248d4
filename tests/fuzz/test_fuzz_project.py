"""Fuzz the .ctui project reader (zip + JSON + npy): truncations, flips, huge sizes,
random and hypothesis mutations, and hostile JSON contents."""

from __future__ import annotations

import json

import numpy as np
import pytest

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign


def warm_up() -> None:
    import ctui.engine.io.project  # noqa: F401
    import hypothesis  # noqa: F401


def seed_project():
    from ctui.engine.io.project import Project

    labels = np.zeros((3, 4, 5), np.uint8)
    labels[1, 1:3, 1:4] = 2
    return Project(
        source_path="/data/ct",
        pipeline={"steps": [{"op": "median", "size": 3}]},
        labels=labels,
        objects=[{"id": 2, "seeds": [[1, 1, 1]], "tolerance": 50}],
        propagation={"direction": "both"},
        drift={"corrections": {}},
        window=(40, 400),
    )


def _zip(members: dict) -> bytes:
    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in members.items():
            zf.writestr(k, v)
    return buf.getvalue()


def campaign(ctx) -> None:
    from ctui.engine.io.project import encode_project, load_project

    proj = seed_project()
    seed = encode_project(proj)
    standard_campaign(ctx, load_project, seed, name="x.ctui", tag="project", flips_every=2)
    # hostile project.json values with valid zip framing
    good = proj.to_json_dict()
    hostile = [None, True, -1, 2**63, 1e308, float("nan"), "x" * 1000, [], {}, [[[]]], [-1, 2, 3], [2**31, 2**31, 2**31], [0, 0, 0]]
    keys = ["version", "source_path", "source_options", "pipeline", "objects", "propagation", "drift", "window", "meta", "labels", "format"]
    npy = encode_project(proj)
    import io
    import zipfile

    with zipfile.ZipFile(io.BytesIO(npy)) as zf:
        labels_member = zf.read("labels.npy")
    for k in keys:
        for v in hostile:
            d = dict(good)
            d[k] = v
            ctx.check(load_project, _zip({"project.json": json.dumps(d), "labels.npy": labels_member}), name="x.ctui", tag="project-json")
    for shape in ([3, 4, 5], [5, 4, 3], [60, 1, 1], [0, 4, 5], [2**20, 2**20, 2**20], [3, 4], [3, 4, 5, 1]):
        for dt in ("uint8", "int16", "<u1", None):
            d = dict(good)
            d["labels"] = {"member": "labels.npy", "shape": shape, "dtype": dt}
            ctx.check(load_project, _zip({"project.json": json.dumps(d), "labels.npy": labels_member}), name="x.ctui", tag="project-shape")
    # member names and duplicates
    ctx.check(load_project, _zip({"project.json": json.dumps(good), "../evil": b"x"}), name="x.ctui", tag="project-json")
    d = dict(good)
    d["labels"] = {"member": "../../etc/passwd", "shape": [3, 4, 5], "dtype": "uint8"}
    ctx.check(load_project, _zip({"project.json": json.dumps(d)}), name="x.ctui", tag="project-json")
    ctx.check(load_project, _zip({"project.json": "[" * 100000 + "]" * 100000}), name="x.ctui", tag="project-json")


@pytest.mark.slow
def test_fuzz_project():
    res = run_campaign("test_fuzz_project", "campaign", examples=fuzz_examples(1000))
    assert_clean("project", res, min_cases=2000)
