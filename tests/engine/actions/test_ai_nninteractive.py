"""``--method nninteractive`` with the real ``nninteractive-client`` against the protocol server of
``tests/engine/actions/ai_server.py`` on 127.0.0.1: the mask ctui writes is what the server answered, voxel for
voxel (points, negative points, a box, a refinement), a lost session is re-established, and every
failure (no server, refused key, server full, a timeout, no client) is one line and exit 2."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("nnInteractive.inference.remote", reason="nninteractive-client (pip install 'ctui[ai]')")

from ai_server import NEG_R, POS_R, PromptServer  # noqa: E402 - after the skip
from support import cli_streams  # noqa: E402
from ctui.engine.actions.segment import METHODS, SegmentOptions, segment  # noqa: E402
from ctui.engine.actions.series import Segmentation  # noqa: E402
from ctui.engine.core.errors import CtuiError  # noqa: E402
from ctui.engine.io.labels import load_labels  # noqa: E402
from ctui.engine.io.series import load  # noqa: E402
from ctui.engine.segment import nninteractive  # noqa: E402

SHAPE = (24, 48, 56)  # (nz, ny, nx)
BODY = (slice(3, 21), slice(6, 42), slice(6, 50))  # value 40; -1000 around it


@pytest.fixture
def server():
    nninteractive.close_sessions()
    srv = PromptServer()
    yield srv
    nninteractive.close_sessions()
    srv.close()


@pytest.fixture
def series(tmp_path) -> Path:
    import nibabel as nib

    data = np.full(SHAPE, -1000, np.int16)
    data[BODY] = 40
    aff = np.diag([-0.8, -0.7, 2.5, 1.0])  # (x, y, z) mm per voxel, RAS: an LPS-like axial stack
    p = tmp_path / "ct.nii.gz"
    nib.save(nib.Nifti1Image(np.ascontiguousarray(data.transpose(2, 1, 0)), aff), str(p))
    return p


def image() -> np.ndarray:
    data = np.full(SHAPE, -1000, np.int16)
    data[BODY] = 40
    return data


def ball(centre_xyz, r) -> np.ndarray:
    x, y, z = centre_xyz
    zz, yy, xx = np.ogrid[:SHAPE[0], :SHAPE[1], :SHAPE[2]]
    return (zz - z) ** 2 + (yy - y) ** 2 + (xx - x) ** 2 <= r * r


def expected(pos=(), neg=()) -> np.ndarray:
    """The test model's answer, computed here from its definition: balls of POS_R voxels inside the body,
    minus balls of NEG_R voxels, in order."""
    m = np.zeros(SHAPE, bool)
    for p in pos:
        m |= ball(p, POS_R) & (image() > 0)
    for q in neg:
        m &= ~ball(q, NEG_R)
    return m


def run_cli(args, capsys):
    capsys.readouterr()
    return cli_streams(args)


def test_registered():
    assert "nninteractive" in METHODS and "prompts" in METHODS["nninteractive"].options


def test_points_and_negative(server, series, tmp_path, capsys):
    mask, proj = tmp_path / "m.nii.gz", tmp_path / "p.ctui"
    rc, out, err = run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url,
                            "--seed", "20,20,10", "--seed", "30,22,12", "--background", "25,21,11",
                            "--mask", str(mask), "--project", str(proj), "--json"], capsys)
    assert rc == 0, err
    got = load_labels(str(mask))[0] == 1
    assert np.array_equal(got, server.returned(SHAPE) != 0)  # what the server answered, voxel for voxel
    assert np.array_equal(got, expected([(20, 20, 10), (30, 22, 12)], [(25, 21, 11)]))
    assert 0 < got.sum() < expected([(20, 20, 10), (30, 22, 12)]).sum()  # the negative point removed voxels
    assert server.log == [("point", (10, 20, 20)), ("point", (12, 22, 30)), ("negative", (11, 21, 25))]
    assert server.requests[:4] == ["/claim", "/capabilities", "/set_image", "/set_target_buffer"]
    assert "/reset_interactions" not in server.requests  # a fresh image needs none (a minimal server may lack it)
    report = json.loads(out)
    obj = report["objects"][0]
    assert obj["voxels"] == int(got.sum()) and obj["range"] is None
    assert obj["message"].endswith("; the server's model licence: CC BY-NC-SA 4.0 (test model)")
    text = zipfile.ZipFile(proj).read("project.json").decode()
    assert server.url not in text and "127.0.0.1" not in text  # the server is never saved


def test_box(server, series, tmp_path, capsys):
    mask = tmp_path / "m.nii.gz"
    rc, _, err = run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url,
                          "--box", "10,12,5,30,28,14", "--mask", str(mask)], capsys)
    assert rc == 0, err
    got = load_labels(str(mask))[0] == 1
    assert np.array_equal(got, server.returned(SHAPE) != 0)
    assert server.log == [("box", [[5, 15], [12, 29], [10, 31]])]  # half-open (z, y, x) ranges
    zz, yy, xx = np.mgrid[:SHAPE[0], :SHAPE[1], :SHAPE[2]] + 0.5
    ell = ((zz - 10) / 5) ** 2 + ((yy - 20.5) / 8.5) ** 2 + ((xx - 20.5) / 10.5) ** 2 <= 1
    assert np.array_equal(got, ell)


def test_refine(server, series, tmp_path, capsys):
    first, second = tmp_path / "a.ctui", tmp_path / "b.ctui"
    mask = tmp_path / "b.nii.gz"
    assert run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url, "--seed", "20,20,10",
                    "--seed", "40,20,10", "--project", str(first)], capsys)[0] == 0
    nninteractive.close_sessions()  # a new command, a new session
    before = expected([(20, 20, 10), (40, 20, 10)])
    n_answers = len(server.answers)
    rc, _, err = run_cli(["segment", str(first), "--method", "nninteractive", "--server", server.url, "--refine",
                          "--background", "22,20,10", "--project", str(second), "--mask", str(mask)], capsys)
    assert rc == 0, err
    assert server.log[-2:] == [("initial", int(before.sum())), ("negative", (10, 20, 22))]
    got = load_labels(str(mask))[0] == 1
    assert np.array_equal(got, expected([(20, 20, 10), (40, 20, 10)], [(22, 20, 10)]))
    (bbox, arr), = server.answers[n_answers:]  # one answer: the negative point's box
    box = tuple(slice(a, b) for a, b in bbox)
    assert np.array_equal(got[box], arr != 0)  # inside the box: the server's voxels
    outside = np.ones(SHAPE, bool)
    outside[box] = False
    assert np.array_equal(got[outside], before[outside]) and before[outside].any()  # outside: untouched


def test_lost_session_cli(server, series, tmp_path, capsys):
    server.expire_next.add("/add_point_interaction")  # the lease is gone when the first prompt arrives
    mask = tmp_path / "m.nii.gz"
    rc, out, err = run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url,
                            "--seed", "20,20,10", "--mask", str(mask), "--json"], capsys)
    assert rc == 0, err
    assert server.claims == 2 and server.images == 2  # claimed again, the image sent again
    got = load_labels(str(mask))[0] == 1
    assert np.array_equal(got, expected([(20, 20, 10)]))
    assert "re-established" in json.loads(out)["objects"][0]["message"]


def test_session_lost_twice_is_one_line(server, series, capsys):
    server.expire_all = True
    rc, _, err = run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url,
                          "--seed", "20,20,10"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "lost the session twice" in err
    assert server.claims == 2


def test_lost_session_keeps_the_object(server):
    """A restart between two prompts (the TUI's clicks): the second claims again, sends the image and
    the object as it stands, then its prompt."""
    vol = load_volume_array()
    res = segment(vol, [(20, 20, 10)], [], options=SegmentOptions(method="nninteractive", server=server.url))
    seg = res.segmentation
    server.forget()
    segment(vol, [(36, 24, 12)], [], options=SegmentOptions(method="nninteractive", server=server.url),
            segmentation=seg, object_ids=[1])
    assert server.claims == 2 and server.images == 2
    assert ("initial", int(expected([(20, 20, 10)]).sum())) in server.log
    assert np.array_equal(seg.labels == 1, expected([(20, 20, 10), (36, 24, 12)]))
    assert seg.undo() is not None and np.array_equal(seg.labels == 1, expected([(20, 20, 10)]))  # one step a prompt


def load_volume_array():
    from ctui.engine.core.volume import Volume

    return Volume(data=image(), spacing=(2.5, 0.7, 0.8))


def test_same_session_reused(server):
    vol = load_volume_array()
    opts = SegmentOptions(method="nninteractive", server=server.url)
    res = segment(vol, [(20, 20, 10)], [], options=opts)
    res2 = segment(vol, [(30, 20, 10)], [], background=[(25, 20, 10)], options=opts,
                   segmentation=res.segmentation, object_ids=[1])
    assert server.claims == 1 and server.images == 1  # the image went once
    assert "licence" in res.objects[0].message() and "licence" not in res2.objects[0].message()  # shown once
    assert np.array_equal(res2.segmentation.labels == 1, expected([(20, 20, 10), (30, 20, 10)], [(25, 20, 10)]))
    nninteractive.close_sessions()
    assert not server.leases and server.requests[-1] == "/release"  # the session is released


def test_edited_object_is_sent_again(server):
    """An object edited between prompts (a brush stroke away from the server's boxes) no longer matches the
    server's copy: it goes as the initial segmentation before the next prompt, so nothing is lost."""
    vol = load_volume_array()
    opts = SegmentOptions(method="nninteractive", server=server.url)
    seg = segment(vol, [(20, 20, 10)], [], options=opts).segmentation
    drawn = np.zeros(SHAPE, bool)
    drawn[15:17, 35:38, 40:44] = True
    seg.apply_mask(drawn, 1, label="brush")
    segment(vol, [(30, 20, 10)], [], options=opts, segmentation=seg, object_ids=[1])
    first = expected([(20, 20, 10)])
    assert server.log[-2:] == [("initial", int((first | drawn).sum())), ("point", (10, 20, 30))]
    assert np.array_equal(seg.labels == 1, expected([(20, 20, 10), (30, 20, 10)]) | drawn)


def _closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.mark.slow
def test_dead_server_one_line_exit_2(series, tmp_path):
    url = f"http://127.0.0.1:{_closed_port()}"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3]), "CTUI_NNI_SERVER": url}
    p = subprocess.run([sys.executable, "-m", "ctui.cli", "segment", str(series), "--method", "nninteractive",
                        "--seed", "20,20,10", "--project", str(tmp_path / "p.ctui")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the nnInteractive server" in lines[0] and "ssh -L" in lines[0]
    assert not (tmp_path / "p.ctui").exists()  # nothing written


@pytest.mark.parametrize("case", ["key", "full", "none"])
def test_errors_one_line(case, series, tmp_path, capsys, monkeypatch):
    nninteractive.close_sessions()
    monkeypatch.delenv("CTUI_NNI_SERVER", raising=False)
    monkeypatch.delenv("CTUI_NNI_KEY", raising=False)
    srv = PromptServer(api_key="s3cret", max_sessions=0 if case == "full" else 2)
    try:
        url = [] if case == "none" else ["--server", srv.url]
        key = ["--key", "s3cret"] if case == "full" else []
        rc, _, err = run_cli(["segment", str(series), "--method", "nninteractive", *url, *key, "--seed", "20,20,10"],
                             capsys)
        assert rc == 2 and len(err.strip().splitlines()) == 1
        want = {"key": "refused the API key (HTTP 401)", "full": "is full (server at capacity (0 sessions))",
                "none": "no nnInteractive server"}[case]
        assert want in err
        if case == "key":  # the key from the environment works
            monkeypatch.setenv("CTUI_NNI_KEY", "s3cret")
            assert run_cli(["segment", str(series), "--method", "nninteractive", *url, "--seed", "20,20,10"],
                           capsys)[0] == 0
    finally:
        nninteractive.close_sessions()
        srv.close()


def test_timeout(server, series, capsys, monkeypatch):
    server.delay_s = 2.0
    monkeypatch.setenv("CTUI_NNI_TIMEOUT", "0.5")
    rc, _, err = run_cli(["segment", str(series), "--method", "nninteractive", "--server", server.url,
                          "--seed", "20,20,10"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "did not answer within 0.5 s" in err
    vol = load_volume_array()
    seg = Segmentation(SHAPE)
    with pytest.raises(CtuiError, match=r"did not answer within 0.5 s"):
        nninteractive.run_prompts(vol, seg, 1, nninteractive.Prompts([(20, 20, 10)]), server=server.url)
    assert not (seg.labels == 1).any()


def test_without_the_client(monkeypatch, server):
    monkeypatch.setitem(sys.modules, "nnInteractive.inference", None)  # as if not installed
    with pytest.raises(CtuiError, match=r"pip install 'ctui\[ai\]'"):
        segment(load_volume_array(), [(20, 20, 10)], [], options=SegmentOptions(method="nninteractive",
                                                                                 server=server.url))


def test_series_file_is_what_was_sent(server, series):
    """The image the server holds is the series ctui loaded, voxel for voxel, as (1, nz, ny, nx)."""
    vol = load(str(series))
    segment(vol, [(20, 20, 10)], [], options=SegmentOptions(method="nninteractive", server=server.url))
    (lease,) = server.leases.values()
    assert lease.image.shape == (1, *SHAPE) and np.array_equal(lease.image[0], vol.data)


@pytest.mark.slow
async def test_tui_clicks_refine_the_object(server, series, tmp_path, monkeypatch):
    """The TUI: method nninteractive (the G panel's choice), S at the cursor sends a positive point, the
    proposal is accepted with a; S elsewhere with a background seed refines the same object (one session,
    the image sent once); u undoes the last accept."""
    from ctui.screens import graphics
    from ctui.screens.app import CtuiApp
    from ctui.screens.session import Session
    from ctui.screens.testing import wait_for, wait_workspace

    monkeypatch.setattr(graphics, "_chosen", "halfblock")
    monkeypatch.setenv("CTUI_AUTOSAVE_DIR", str(tmp_path / "autosave"))
    monkeypatch.setenv("CTUI_NNI_SERVER", server.url)
    monkeypatch.chdir(tmp_path)
    vol = load(str(series))
    s = Session(vol, source_path=str(series), z=10, y=20, x=20)
    s.segment_options = {"method": "nninteractive"}
    app = CtuiApp(session=s, autosave_s=1e9)
    async with app.run_test(size=(160, 50)) as pilot:
        await wait_workspace(pilot, app)
        ws = app.workspace
        s.z, s.y, s.x = 10, 20, 20
        await pilot.press("S")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=60, what="the first proposal")
        status = str(ws.query_one("#status").render())
        assert "nnInteractive: 1 prompt (image sent)" in status and "model licence: CC BY-NC-SA" in status
        await pilot.press("a")
        await pilot.pause()
        first = expected([(20, 20, 10)])
        assert np.array_equal(s.seg.labels == s.current, first)
        s.z, s.y, s.x = 12, 22, 30
        s.background_seeds.append((25, 21, 11))
        await pilot.press("S")
        await wait_for(pilot, lambda: ws.pending.proposal is not None, timeout=60, what="the second proposal")
        status = str(ws.query_one("#status").render())
        assert "nnInteractive: 2 prompts," in status and "licence" not in status  # the licence once a session
        await pilot.press("a")
        await pilot.pause()
        assert np.array_equal(s.seg.labels == s.current, expected([(20, 20, 10), (30, 22, 12)], [(25, 21, 11)]))
        assert np.array_equal(s.seg.labels == s.current, server.returned(SHAPE) != 0)
        assert server.claims == 1 and server.images == 1
        assert server.log == [("point", (10, 20, 20)), ("point", (12, 22, 30)), ("negative", (11, 21, 25))]
        await pilot.press("u")
        await pilot.pause()
        assert np.array_equal(s.seg.labels == s.current, first)
