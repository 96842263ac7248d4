"""Fuzz the GIPL loader (ctui.engine.io.series.gipl through load() and the label-map reader): truncations,
bit flips, huge 32-bit values, random and hypothesis mutations of a valid .gipl and .gipl.gz, and header
fields set to hostile values (huge dims, unknown or complex image types, NaN/zero spacing, wrong magic).
Same rule and harness as the other fuzzers (see test_fuzz_harness): a Volume or a one-line CtuiError."""

from __future__ import annotations

import gzip
import struct

import numpy as np
import pytest

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign


def warm_up() -> None:
    import hypothesis  # noqa: F401

    from ctui.engine.io.series import gipl  # noqa: F401


def seed() -> bytes:
    """A 3 x 16 x 16 int16 GIPL as ITK writes it: 256-byte big-endian header, then the voxels."""
    h = bytearray(256)
    h[0:8] = struct.pack(">4H", 16, 16, 3, 1)
    h[8:10] = struct.pack(">H", 15)
    h[10:26] = struct.pack(">4f", 0.7, 0.7, 2.5, 1.0)
    h[204:236] = struct.pack(">4d", -10.0, -20.0, 5.0, 0.0)
    h[252:256] = struct.pack(">I", 0xEFFFE9B0)
    vol = (np.arange(3 * 16 * 16).reshape(3, 16, 16) % 2000 - 1000).astype(">i2")
    return bytes(h) + vol.tobytes()


def _field(data: bytes, offset: int, fmt: str, *values) -> bytes:
    b = bytearray(data)
    struct.pack_into(fmt, b, offset, *values)
    return bytes(b)


def campaign(ctx) -> None:
    from ctui.engine.io.labels import load_labels
    from ctui.engine.io.series import load

    s = seed()
    standard_campaign(ctx, load, s, name="v.gipl", tag="gipl", flips_every=8, trunc_limit=100)
    standard_campaign(ctx, load, gzip.compress(s), name="v.gipl.gz", tag="gipl.gz", flips_every=4, trunc_limit=100)
    hostile = [("dims", 0, ">4H", v) for v in ((65535, 65535, 65535, 1), (0, 16, 3, 1), (16, 16, 0, 0),
                                                (16, 16, 3, 65535), (1, 1, 65535, 1))]
    hostile += [("type", 8, ">H", (v,)) for v in (0, 1, 7, 8, 31, 65, 144, 192, 200, 65535)]
    hostile += [("spacing", 10, ">3f", v) for v in ((0, 0, 0), (-1, 1, 1), (float("nan"), 1, 1),
                                                    (float("inf"), 1e38, 1e-38))]
    hostile += [("origin", 204, ">3d", v) for v in ((float("nan"),) * 3, (1e308, -1e308, 0))]
    hostile += [("magic", 252, ">I", (v,)) for v in (0, 0x2AE389B8, 0xB0E9FFEF)]
    for what, off, fmt, v in hostile:
        data = _field(s, off, fmt, *v)
        for reader in (load, load_labels):
            ctx.check(reader, data, name="v.gipl", tag=f"gipl-{what}", note=str(v))
            ctx.check(reader, gzip.compress(data), name="v.gipl.gz", tag=f"gipl.gz-{what}", note=str(v))
    # a gzip bomb behind a small header, and a header declaring more than the stream holds
    bomb = gzip.compress(s[:256] + bytes(64 * 2**20), 9)
    ctx.check(load, bomb, name="bomb.gipl.gz", tag="gipl-bomb", mem_budget=4 * 64 * 2**20 * 2)
    ctx.check(load, gzip.compress(_field(s, 0, ">4H", 4096, 4096, 64, 1)), name="big.gipl.gz", tag="gipl-bomb")


@pytest.mark.slow
def test_fuzz_gipl():
    res = run_campaign("test_fuzz_gipl", "campaign", examples=fuzz_examples(60))
    assert_clean("gipl", res, min_cases=500)
