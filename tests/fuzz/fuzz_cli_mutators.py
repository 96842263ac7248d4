"""Mutators of the command fuzzer (tests/fuzz/fuzz_cli.py): byte-level, text-header,
NIfTI-field, gzip-payload and project.json mutations of a seed file, and hypothesis-drawn
integer edits. A seed is anything with ``kind``, ``main`` and ``files`` (fuzz_cli.Seed)."""

from __future__ import annotations

import gzip
import io
import json
import os
import re
import struct
import sys
import zipfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
INTERESTING_TEXT = ["nan", "NaN", "inf", "-inf", "0", "-0", "-1", "1e308", "-1e308", "1e-300", "99999999",
                    "2147483648", "4294967296", "65535", "", "x", "1,2", "3 3", "0 0 0", "-5 4 3", "1e9 1 1"]


def _byte_mutate(data: bytes, rng) -> bytes:
    sys.path.insert(0, str(HERE))
    from test_fuzz_harness import mutate

    r = rng.random()
    if r < 0.15 and data:  # truncation
        return data[: int(rng.integers(0, len(data)))]
    return mutate(data, rng)


def _text_mutate(text: str, rng) -> str:
    lines = text.split("\n")
    for _ in range(int(rng.integers(1, 3))):
        if not lines:
            break
        i = int(rng.integers(0, len(lines)))
        op = rng.random()
        line = lines[i]
        if op < 0.6:
            nums = list(re.finditer(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", line))
            val = INTERESTING_TEXT[int(rng.integers(0, len(INTERESTING_TEXT)))]
            if nums:
                m = nums[int(rng.integers(0, len(nums)))]
                lines[i] = line[: m.start()] + val + line[m.end():]
            elif ":" in line or "=" in line:
                sep = ":" if ":" in line else "="
                lines[i] = line.split(sep, 1)[0] + sep + " " + val
        elif op < 0.75:
            del lines[i]
        elif op < 0.9:
            lines.insert(i, line)
        else:
            j = int(rng.integers(0, len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines)


def _split_header(data: bytes, kind: str) -> tuple[bytes, bytes]:
    """(text header, binary rest) for formats with a text header; (b"", data) otherwise."""
    if kind == "nrrd" or (kind == "ply"):
        marker = b"\n\n" if kind == "nrrd" else b"end_header\n"
        i = data.find(marker)
        if i >= 0:
            return data[: i + len(marker)], data[i + len(marker):]
    if kind in ("mhd", "stl-ascii", "obj"):
        return data, b""
    return b"", data


HOSTILE_JSON = [None, True, -1, 0, 2**63, 1e308, -1e308, "x", "", [], {}, [[[]]], [-1, 2, 3], [0, 0, 0],
                [1e308, 1, 1], [2**31, 2**31, 2**31], ["a", "b", "c"], [1, 2], [1, 2, 3, 4]]


def _project_mutate(data: bytes, rng) -> bytes:
    """A project whose project.json has one field (or one list item) replaced by a hostile value."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            members = {n: zf.read(n) for n in zf.namelist()}
        doc = json.loads(members["project.json"])
    except Exception:  # noqa: BLE001 - not a valid seed: fall back to bytes
        return _byte_mutate(data, rng)
    paths: list[list] = []

    def walk(o, path):
        paths.append(path)
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, path + [k])
        elif isinstance(o, list):
            for i, v in enumerate(o[:8]):
                walk(v, path + [i])

    walk(doc, [])
    path = paths[int(rng.integers(1, len(paths)))] if len(paths) > 1 else []
    val = HOSTILE_JSON[int(rng.integers(0, len(HOSTILE_JSON)))]
    if path:
        o = doc
        for k in path[:-1]:
            o = o[k]
        if rng.random() < 0.1 and isinstance(o, dict):
            del o[path[-1]]
        else:
            o[path[-1]] = val
    members["project.json"] = json.dumps(doc).encode()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    return buf.getvalue()


def mutate_seed(seed: Any, rng) -> tuple[bytes, str]:
    """A mutated copy of the seed's main file and the mutator's name."""
    data = seed.files[seed.main]
    r = rng.random()
    if seed.kind == "project" and r < 0.6:
        return _project_mutate(data, rng), "project-json"
    if data[:2] == b"\x1f\x8b" and r < 0.6:
        try:
            inner = gzip.decompress(data)
        except OSError:
            inner = None
        if inner is not None:
            return gzip.compress(_inner_mutate(inner, seed.kind, rng), 6), "gzip-payload"
    if r < 0.75:
        return _inner_mutate(data, seed.kind, rng), "structured"
    return _byte_mutate(data, rng), "bytes"


NIFTI_FIELDS = [*[(40 + 2 * i, "<h") for i in range(8)], (70, "<h"), (72, "<h"), *[(76 + 4 * i, "<f") for i in range(8)],
                (108, "<f"), (112, "<f"), (116, "<f"), (252, "<h"), (254, "<h"), *[(280 + 4 * i, "<f") for i in range(12)]]
NIFTI_VALUES = [0, 1, 2, 3, 4, 7, 8, 16, 48, 64, 255, 256, -1, -5, 32767, -32768, float("nan"), float("inf"), -float("inf"),
                0.0, -1.0, 1e-30, 1e30, 0.5, 2.0]


def _inner_mutate(data: bytes, kind: str, rng) -> bytes:
    if kind == "nifti" and len(data) >= 348 and rng.random() < 0.7:
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 3))):
            off, fmt = NIFTI_FIELDS[int(rng.integers(0, len(NIFTI_FIELDS)))]
            v = NIFTI_VALUES[int(rng.integers(0, len(NIFTI_VALUES)))]
            if fmt == "<h":
                v = int(v) if isinstance(v, int) else int(rng.integers(-3, 300))
                v = max(-32768, min(32767, v))
            struct.pack_into(fmt, b, off, v)
        return bytes(b)
    head, rest = _split_header(data, kind)
    if head and rng.random() < 0.8:
        return _text_mutate(head.decode("latin-1"), rng).encode("latin-1") + rest
    return _byte_mutate(data, rng)


def hypothesis_inputs(seeds: list[Any], n: int) -> list[tuple[Any, bytes, str]]:
    """``n`` structured mutations drawn by hypothesis (derandomized: the same cases every
    CI run unless CTUI_FUZZ_RANDOM=1): a seed, up to 6 little-endian 1/2/4-byte edits of
    interesting values, an optional insertion and an optional cut."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    interesting = st.sampled_from([0, 1, 2, 3, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0x8000, 0xFFFF, 0x10000,
                                   0x7FFFFFFF, 0x80000000, 0xFFFFFFFF])
    frac = st.floats(0, 1, allow_nan=False)
    edit = st.tuples(frac, st.one_of(interesting, st.integers(0, 2**32 - 1)), st.sampled_from([1, 2, 4]))
    drawn: list[tuple[Any, bytes, str]] = []

    @settings(max_examples=n, deadline=None, database=None, derandomize=os.environ.get("CTUI_FUZZ_RANDOM") != "1",
              suppress_health_check=list(HealthCheck))
    @given(k=st.integers(0, len(seeds) - 1), edits=st.lists(edit, max_size=6),
           insert=st.one_of(st.none(), st.tuples(frac, st.binary(max_size=40))), cut=st.one_of(st.none(), frac))
    def draw(k, edits, insert, cut):
        seed = seeds[k]
        b = bytearray(seed.files[seed.main])
        for f, val, width in edits:
            off = int(f * max(len(b) - width, 0))
            if off + width <= len(b):
                struct.pack_into({1: "<B", 2: "<H", 4: "<I"}[width], b, off, val & ((1 << (8 * width)) - 1))
        if insert is not None:
            i = int(insert[0] * len(b))
            b[i:i] = insert[1]
        if cut is not None:
            del b[int(cut * len(b)):]
        drawn.append((seed, bytes(b), "hypothesis"))

    draw()
    return drawn[:n]


