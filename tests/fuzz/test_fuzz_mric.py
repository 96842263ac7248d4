"""Fuzz the MRIC reader: truncation at every offset, bit flips, huge counts, random
and hypothesis-driven mutations of a small valid file (see test_fuzz_harness)."""

from __future__ import annotations

import numpy as np
import pytest

from test_fuzz_harness import assert_clean, fuzz_examples, run_campaign, standard_campaign


def warm_up() -> None:
    import ctui.engine.io.mric  # noqa: F401
    import hypothesis  # noqa: F401


def seed_file(tmp) -> bytes:
    from ctui.engine.io.mric import write_mric

    slices = [
        [[np.array([[0, 0], [3, 1], [2, 2]])], [np.array([[4, 4]]), np.array([[1, 1], [2, 1], [5, 3]])]],
        [],
        [[np.zeros((0, 2))]],
        [[np.array([[5, 4]])]],
    ]
    p = write_mric(tmp, slices, width=5, height=4, axis=(1, 2), image=np.arange(20).reshape(4, 5))
    return p.read_bytes()


def campaign(ctx) -> None:
    from ctui.engine.io.mric import read_mric

    seed = seed_file(ctx.tmp("seed.mric"))
    standard_campaign(ctx, read_mric, seed, name="x.mric", tag="mric")
    # header counts pushed to every interesting value
    import struct

    for off in (17, 21, 25, 37 + 20, 37 + 24, 37 + 28):
        for v in (-(2**31), -1, 0, 1, 2**15, 2**16, 2**24, 2**31 - 1):
            b = bytearray(seed)
            struct.pack_into("<i", b, off, v)
            ctx.check(read_mric, bytes(b), name="x.mric", tag="mric-count")


@pytest.mark.slow
def test_fuzz_mric():
    res = run_campaign("test_fuzz_mric", "campaign", examples=fuzz_examples(1500))
    assert_clean("mric", res, min_cases=2500)
