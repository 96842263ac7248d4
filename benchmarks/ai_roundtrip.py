"""nnInteractive round trips on loopback: claim, image upload and prompts for a 134 x 512 x 512 series.

The server is the protocol server of ``tests/engine/actions/ai_server.py`` (its "model" is a ball around the
point: a few ms), on 127.0.0.1. Two clients side by side in one run:

* peer: the bare ``nninteractive-client`` session (what SlicerNNInteractive drives): claim,
  ``set_image``, ``set_target_buffer``, then ``add_point_interaction``;
* ctui: ``actions.segment.segment(..., method="nninteractive")``, the same calls plus the object
  check (is the server's copy the object?) and writing the returned box into the Segmentation as
  an undo step.

For each prompt: the round trip, the server's own time for it (model + packing the answer, timed
inside the server), and what the round trip adds to it. Goal: a prompt adds < 50 ms to the
server's own time. Bytes sent and received are counted by the server (bodies + ~200 bytes of
headers a request).

    python benchmarks/ai_roundtrip.py [--shape 134,512,512] [--prompts 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "engine" / "actions"))
sys.path.insert(0, str(ROOT))

from ai_server import PromptServer  # noqa: E402
from ctui.engine.actions.segment import SegmentOptions, segment  # noqa: E402
from ctui.engine.core.volume import Volume  # noqa: E402
from ctui.engine.segment import nninteractive  # noqa: E402


def phantom(shape: tuple[int, int, int]) -> np.ndarray:
    """A CT-like int16 series: air, an elliptic body of soft tissue with noise (sd 15 HU), a brighter organ."""
    nz, ny, nx = shape
    rng = np.random.default_rng(0)
    yy, xx = np.ogrid[:ny, :nx]
    body = ((yy - ny / 2) / (ny * 0.4)) ** 2 + ((xx - nx / 2) / (nx * 0.45)) ** 2 <= 1
    organ = ((yy - ny * 0.45) / (ny * 0.12)) ** 2 + ((xx - nx * 0.4) / (nx * 0.1)) ** 2 <= 1
    out = np.full(shape, -1000, np.int16)
    for z in range(nz):
        sl = np.where(body, 40, -1000) + np.where(organ, 100, 0)
        out[z] = (sl + rng.normal(0, 15, (ny, nx)) * body).astype(np.int16)
    return out


def points(shape: tuple[int, int, int], n: int) -> list[tuple[int, int, int]]:
    nz, ny, nx = shape
    return [(int(nx * 0.4) + 3 * i, int(ny * 0.45), nz // 2 + i) for i in range(n)]


def peer(srv: PromptServer, data: np.ndarray, pts: list[tuple[int, int, int]]) -> dict:
    from nnInteractive.inference.remote import nnInteractiveRemoteInferenceSession

    out: dict = {}
    b0 = (srv.bytes_in, srv.bytes_out)
    t = time.perf_counter()
    c = nnInteractiveRemoteInferenceSession(srv.url)
    out["claim"] = time.perf_counter() - t
    t = time.perf_counter()
    c.set_image(data[None], {"spacing": [2.5, 0.7, 0.7]})
    c.set_target_buffer(np.zeros(data.shape, np.uint8))
    out["upload"] = time.perf_counter() - t
    out["upload_bytes"] = (srv.bytes_in - b0[0], srv.bytes_out - b0[1])
    trips, own, sizes = [], [], []
    for x, y, z in pts:
        m0, b1 = srv.model_s, (srv.bytes_in, srv.bytes_out)
        t = time.perf_counter()
        c.add_point_interaction((z, y, x), include_interaction=True)
        trips.append(time.perf_counter() - t)
        own.append(srv.model_s - m0)
        sizes.append((srv.bytes_in - b1[0], srv.bytes_out - b1[1]))
    c.close()
    return out | {"trips": trips, "own": own, "sizes": sizes}


def ctui(srv: PromptServer, data: np.ndarray, pts: list[tuple[int, int, int]]) -> dict:
    vol = Volume(data=data, spacing=(2.5, 0.7, 0.7))
    opts = SegmentOptions(method="nninteractive", server=srv.url)
    out: dict = {}
    b0 = (srv.bytes_in, srv.bytes_out)
    t = time.perf_counter()
    res = segment(vol, [pts[0]], [], options=opts)  # claim + upload + the first prompt
    out["first"] = time.perf_counter() - t
    out["first_bytes"] = (srv.bytes_in - b0[0], srv.bytes_out - b0[1])
    seg = res.segmentation
    trips, own, sizes = [], [], []
    for p in pts[1:]:
        m0, b1 = srv.model_s, (srv.bytes_in, srv.bytes_out)
        t = time.perf_counter()
        segment(vol, [p], [], options=opts, segmentation=seg, object_ids=[1])
        trips.append(time.perf_counter() - t)
        own.append(srv.model_s - m0)
        sizes.append((srv.bytes_in - b1[0], srv.bytes_out - b1[1]))
    nninteractive.close_sessions()
    return out | {"trips": trips, "own": own, "sizes": sizes, "voxels": int(np.count_nonzero(seg.labels == 1))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shape", default="134,512,512")
    ap.add_argument("--prompts", type=int, default=6)
    a = ap.parse_args()
    shape = tuple(int(v) for v in a.shape.split(","))
    data = phantom(shape)  # type: ignore[arg-type]
    pts = points(shape, a.prompts)  # type: ignore[arg-type]
    srv = PromptServer()
    try:
        p = peer(srv, data, pts)
        c = ctui(srv, data, pts)
    finally:
        srv.close()
    mb = data.nbytes / 1e6
    ms = 1000.0
    print(f"series {shape[0]}x{shape[1]}x{shape[2]} int16 ({mb:.0f} MB), loopback, {a.prompts} prompts, medians")
    print(f"peer (bare client): claim {p['claim'] * ms:.0f} ms, image upload {p['upload'] * ms:.0f} ms, "
          f"sent {p['upload_bytes'][0] / 1e6:.1f} MB, received {p['upload_bytes'][1]} B")
    print(f"ctui: claim + upload + first prompt {c['first'] * ms:.0f} ms, sent {c['first_bytes'][0] / 1e6:.1f} MB, "
          f"received {c['first_bytes'][1]} B")
    for name, r in (("peer", p), ("ctui", c)):
        trip, own = statistics.median(r["trips"]), statistics.median(r["own"])
        sent = statistics.median(s[0] for s in r["sizes"])
        got = statistics.median(s[1] for s in r["sizes"])
        print(f"{name}: prompt round trip {trip * ms:.1f} ms, server's own {own * ms:.1f} ms, "
              f"added {(trip - own) * ms:.1f} ms (goal < 50), sent {sent:.0f} B, received {got:.0f} B a prompt")


if __name__ == "__main__":
    main()
