"""Batch jobs on Dask: :func:`run_batch` (``ctui batch MANIFEST.csv --out RESULTS.csv``).

Manifest: a CSV with one row per job and the columns

=============  ==========================================================================
series         series folder/file (anything ``ctui open`` loads); required
seed           "X,Y,Z" voxel (column, row, slice); required
range          "LO:HI" in-range values (HU for CT); empty or "auto": from the seed's neighbourhood
method         "fill" (default), "grow" or "levelset" (:func:`ctui.engine.actions.segment.segment`)
mode           "slice" (propagation slice by slice, default) or "3d"
background     "X,Y,Z[;X,Y,Z]" background seeds (outside the object)
filter         filter steps "NAME[:key=value,...]" separated by ";" (as ``ctui segment --filter``)
outdir         folder for the job's project and mesh (default: ``<RESULTS>-outputs``)
sections       "auto": cross-sections along the automatic centreline as well
name           job name (default: the series' folder name); outputs are ``<name>-<key>``
=============  ==========================================================================

Each job loads its series, segments one object, measures it (voxel and mesh volume,
area; sections when asked) and writes ``<name>-<key>.ctui`` and ``<name>-<key>.stl`` to its
outdir; ``key`` hashes the job's inputs. Jobs run on a ``dask.distributed`` cluster: a
:class:`distributed.LocalCluster` of ``workers`` processes by default, or the scheduler at
``scheduler`` (``tcp://HOST:PORT``). Rows are written to RESULTS.csv (atomically, the
whole file) as jobs finish (``as_completed``); a failed job gets ``status`` "failed" and
its one-line error, and the others go on. A second run skips the jobs whose row says "ok"
and whose outputs are still there.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import logging
import os
import stat
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.actions import defaults
from ctui.engine.actions.measure import measure_object
from ctui.engine.actions.opened import Opened, existing_path
from ctui.engine.actions.options import parse_pair
from ctui.engine.actions.project import new_project, propagation_record, save_project
from ctui.engine.actions.segment import METHODS, SegmentOptions, segment
from ctui.engine.actions.vessel import vessel
from ctui.engine.io.meshes import save_mesh
from ctui.engine.io.series import load
from ctui.engine.segment.pipeline import Pipeline, parse_filter_spec
from ctui.engine.core.atomic import check_output, check_outputs, write_text
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.progress import Progress, report
from ctui.engine.core.safetext import csv_cell

MANIFEST_COLUMNS = ("series", "seed", "range", "method", "mode", "background", "filter", "outdir", "sections", "name",
                    "start", "end", "via")  # start, end "X,Y,Z;..." and via "X,Y,Z;...": a vessel (actions.vessel)
WRITE_EVERY_S = 2.0  # RESULTS.csv rewritten (atomically) at most this often while jobs finish, and at the end
RESULT_COLUMNS = ("job", "name", "series", "seed", "range", "method", "status", "error", "voxels", "volume_voxels_ml",
                  "volume_mesh_ml", "area_mm2", "path_length_mm", "section_area_min_mm2", "section_area_max_mm2",
                  "slices", "project", "mesh", "seconds", "cpu_seconds")
#: thread-count variables set to 1 in local worker processes: N workers use N cores, not N x all
SINGLE_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
MODES = defaults.PROPAGATION_MODES


@dataclass
class Job:
    """One manifest row, parsed. ``key``: a hash of the inputs naming the outputs."""

    row: int
    series: str
    seed: tuple[int, int, int]
    range: tuple[float, float] | None
    method: str = "fill"
    mode: str = "slice"
    background: list[tuple[int, int, int]] = field(default_factory=list)
    filters: list[str] = field(default_factory=list)
    outdir: str = ""
    sections: bool = False
    name: str = ""
    error: str = ""  # a manifest error: the job is reported failed without running
    vessel: tuple | None = None  # (start, ends, vias) voxels (x, y, z): a vessel row (actions.vessel), not a seed

    @property
    def key(self) -> str:
        text = "|".join(map(str, (os.path.abspath(self.series), self.seed, self.range, self.method, self.mode,
                                  self.background, self.filters, self.sections)))
        text += f"|{self.vessel}" if self.vessel else ""
        return hashlib.sha1(text.encode("utf-8", "surrogateescape")).hexdigest()[:10]

    @property
    def stem(self) -> str:
        return f"{self.name}-{self.key}"

    def outputs(self) -> tuple[str, str]:
        return (os.path.join(self.outdir, self.stem + ".ctui"), os.path.join(self.outdir, self.stem + ".stl"))


# =========================================================================== manifest
def _xyz(text: str, what: str) -> tuple[int, int, int]:
    parts = [v for v in str(text).replace(" ", "").split(",") if v != ""]
    try:
        x, y, z = (int(float(v)) for v in parts)
    except ValueError:
        raise CtuiError(f"{what} {text!r}: expected X,Y,Z (column,row,slice)") from None
    return x, y, z


def _range(text: str) -> tuple[float, float] | None:
    if text.strip().lower() in ("", "auto"):
        return None  # the segment action takes the range from the seed's neighbourhood
    a, b = parse_pair(text, "range", example="150:300")
    if a > b:
        raise CtuiError(f"range {text!r}: LO is above HI")
    return a, b


def _job(n: int, row: dict, base: Path, default_outdir: str) -> Job:
    get = {k: str(row.get(k) or "").strip() for k in MANIFEST_COLUMNS}
    series = get["series"]
    if series and not os.path.isabs(series):
        series = str(base / series)
    outdir = get["outdir"] or default_outdir
    if not os.path.isabs(outdir):
        outdir = str(base / outdir)
    name = get["name"] or (Path(series.rstrip("/")).name if series else f"row{n}")
    job = Job(n, series, (0, 0, 0), (0.0, 0.0), outdir=outdir, name="".join(c if c.isalnum() or c in "._-" else "_"
                                                                             for c in name)[:60] or f"row{n}")
    try:
        if not series:
            raise CtuiError("no series")
        if get["start"]:
            ends = [_xyz(v, "end") for v in get["end"].split(";") if v.strip()]
            if not ends:
                raise CtuiError("a vessel row (start) needs an end")
            job.vessel = (_xyz(get["start"], "start"), ends, [_xyz(v, "via") for v in get["via"].split(";") if v.strip()])
        job.seed = job.vessel[0] if job.vessel else _xyz(get["seed"], "seed")
        job.range = _range(get["range"])
        job.method = (get["method"] or "fill").lower()
        if job.method not in METHODS:
            raise CtuiError(f"method {get['method']!r}: one of {', '.join(METHODS)}")
        job.mode = (get["mode"] or "slice").lower()
        if job.mode not in MODES:
            raise CtuiError(f"mode {get['mode']!r}: one of {', '.join(MODES)}")
        job.background = [_xyz(v, "background") for v in get["background"].split(";") if v.strip()]
        job.filters = [v.strip() for v in get["filter"].split(";") if v.strip()]
        job.sections = get["sections"].lower() in ("auto", "yes", "true", "1")
    except CtuiError as exc:
        job.error = str(exc)
    return job


def read_manifest(path: str | os.PathLike, *, default_outdir: str = "") -> list[Job]:
    """Parse MANIFEST.csv (relative paths are relative to its folder). CtuiError when unreadable."""
    p = Path(path)
    text = _read_text(p, what="manifest")
    reader = csv.DictReader(io.StringIO(text))
    try:
        cols = [c.strip().lower() for c in reader.fieldnames or []]
    except csv.Error as exc:
        raise CtuiError(f"not a readable CSV manifest ({exc})", path=p) from None
    missing = [c for c in ("series", "seed") if c not in cols and not (c == "seed" and "start" in cols)]
    if missing:
        raise CtuiError(f"the manifest lacks the column(s) {', '.join(missing)} (columns: series, seed, "
                        "optional range, background, filter, outdir, sections, name)", path=p)
    reader.fieldnames = cols
    try:
        return [_job(n, row, p.parent.resolve(), default_outdir) for n, row in enumerate(reader, start=1)]
    except csv.Error as exc:  # a field over the csv module's 131,072 characters, a stray NUL...
        raise CtuiError(f"not a readable CSV manifest (line {reader.line_num}: {exc})", path=p) from None


def refuse_cross_writes(jobs: list[Job]) -> int:
    """Mark failed (``job.error``) each job whose outdir or outputs lie inside (or are) another row's
    series (folder or file): its files would join that series. Returns how many were refused.
    Each series is stat'ed once and each output's folders once: linear in rows."""
    ids: dict[tuple[int, int], Job] = {}
    for j in jobs:
        if j.series:
            try:
                st = os.stat(j.series)
            except (OSError, ValueError):
                continue
            ids.setdefault((st.st_dev, st.st_ino), j)
    refused = 0
    for j in jobs:
        if j.error or not ids:
            continue
        for out in (j.outdir, *j.outputs()):
            other = _inside_other(out, ids, j)
            if other is not None:
                j.error = (f"its output {out} is inside row {other.row}'s series {other.series}; refusing to write "
                           "into another series, choose another outdir")
                refused += 1
                break
    return refused


def _inside_other(path: str, ids: dict[tuple[int, int], Job], job: Job) -> Job | None:
    """The job (not ``job``) whose series is ``path`` or one of its folders, else None."""
    cur = os.path.realpath(path)
    while True:
        try:
            st = os.stat(cur)
            other = ids.get((st.st_dev, st.st_ino))
            if other is not None and other is not job and os.path.realpath(other.series) != os.path.realpath(job.series):
                return other
        except (OSError, ValueError):
            pass
        parent = os.path.dirname(cur)
        if parent == cur:
            return None
        cur = parent


MAX_TABLE_BYTES = 64 << 20  # a manifest or results table larger than this is not one


def _read_text(p: Path, *, what: str) -> str:
    """A regular file's text (at most MAX_TABLE_BYTES): UTF-8 (with or without BOM), UTF-16
    with a BOM, else Latin-1 (every byte is a character). A device, FIFO or folder is
    refused (``/dev/zero`` would never end, a FIFO blocks)."""
    try:
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode):
            raise CtuiError(f"the {what} is not a regular file", path=p)
        if st.st_size > MAX_TABLE_BYTES:
            raise CtuiError(f"the {what} is {st.st_size} bytes: over the {MAX_TABLE_BYTES >> 20} MB a table may have",
                            path=p)
        with open(p, "rb") as fh:
            raw = fh.read(MAX_TABLE_BYTES + 1)
    except OSError as exc:
        raise CtuiError(f"cannot read ({exc.strerror or exc})", path=p) from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            raise CtuiError(f"the {what} starts with a UTF-16 mark but is not UTF-16 text", path=p) from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


# =========================================================================== one job
def _segment(volume: Any, job: Job) -> tuple[np.ndarray, dict, dict]:
    """(labels uint8, pipeline dict, propagation dict) of one object from the job's seed (the segment action)."""
    try:
        pipeline = Pipeline([parse_filter_spec(s) for s in job.filters], domain="hu")
    except ValueError as exc:
        raise CtuiError(f"filter: {exc}") from None
    res = segment(volume, [job.seed], [job.range] if job.range is not None else [], background=job.background,
                  pipeline=pipeline,
                  options=SegmentOptions(method=job.method, mode=job.mode), names=[job.name])
    return res.segmentation.labels, pipeline.to_dict(), propagation_record(res.settings)


def _vessel(volume: Any, job: Job) -> tuple[np.ndarray, dict, dict]:
    """(labels uint8, pipeline dict, propagation dict) of a vessel row (the vessel action, ``ctui vessel``)."""
    if job.vessel is None:
        raise CtuiError(f"row {job.name!r} is not a vessel row")
    start, ends, vias = job.vessel
    res = vessel(volume, start=start, ends=ends, vias=vias, value_range=job.range)
    if res.mask is None:
        raise CtuiError("the vessel action returned no mask")
    return res.mask.astype(np.uint8), {}, propagation_record([])


def run_job(job: Job) -> dict:
    """Run one job (on a Dask worker); returns its RESULTS row. Never raises: a failure is a row."""
    t0, c0 = time.perf_counter(), time.process_time()
    row: dict[str, Any] = {"job": job.key, "name": job.name, "series": job.series, "seed": ",".join(map(str, job.seed)),
                           "range": "auto" if job.range is None else f"{job.range[0]:g}:{job.range[1]:g}",
                           "method": f"{job.method}/{job.mode}"}
    try:
        if job.error:
            raise CtuiError(job.error)
        row.update(_run(job))
        row["status"] = "ok"
    except Exception as exc:  # noqa: BLE001 - one job's failure must not stop the batch
        msg = " ".join(str(exc).split()) or type(exc).__name__
        row.update(status="failed", error=msg if isinstance(exc, CtuiError) else f"{type(exc).__name__}: {msg}")
    row["seconds"] = round(time.perf_counter() - t0, 3)
    row["cpu_seconds"] = round(time.process_time() - c0, 3)  # the worker process's CPU (all its threads)
    return row


def _run(job: Job) -> dict:
    volume = load(existing_path(job.series, "series folder or file"))
    labels, pipeline, propagation = _vessel(volume, job) if job.vessel else _segment(volume, job)
    project = new_project(volume, source_path=job.series, labels=labels, pipeline=pipeline, propagation=propagation,
                          objects=[{"id": 1, "name": job.name, "color": [230, 60, 60], "seeds": [list(job.seed)]}])
    opened = Opened.of_volume(volume, labels, path=job.series, project=project)
    m = measure_object(opened, object=1, path="auto" if job.sections else None)
    proj_path, mesh_path = job.outputs()
    check_outputs({"project": proj_path, "mesh": mesh_path}, inputs=[job.series])  # never into the series folder
    os.makedirs(job.outdir, exist_ok=True)
    save_project(proj_path, project)
    mesh = m.stats.get("mesh") if m.stats else None
    if mesh is None:
        raise CtuiError("the object gave no surface")
    save_mesh(mesh_path, mesh)
    zs = np.flatnonzero((labels == 1).any(axis=(1, 2)))
    areas = [s["area_mm2"] for s in m.sections if s.get("area_mm2") is not None]
    return {"voxels": int(np.count_nonzero(labels == 1)), "volume_voxels_ml": _r(m.volume_ml.get("voxels")),
            "volume_mesh_ml": _r(m.volume_ml.get("mesh")), "area_mm2": _r(m.area_mm2, 3),
            "path_length_mm": _r(m.path_length_mm, 3), "section_area_min_mm2": _r(min(areas), 3) if areas else None,
            "section_area_max_mm2": _r(max(areas), 3) if areas else None,
            "slices": f"{zs[0]}:{zs[-1]}" if zs.size else "", "project": proj_path, "mesh": mesh_path, "error": ""}


def _r(v: Any, nd: int = 6) -> Any:
    return None if v is None else round(float(v), nd)


# =========================================================================== results
def read_results(path: str | os.PathLike) -> dict[str, dict]:
    """{job key: row} of an existing RESULTS.csv ({} when absent or unreadable)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
        return {r["job"]: r for r in csv.DictReader(io.StringIO(text)) if r.get("job")}
    except (OSError, UnicodeDecodeError, csv.Error, ValueError):  # absent, or not a table ctui wrote: rewritten
        return {}


def write_results(path: str | os.PathLike, rows: list[dict]) -> None:
    """Write all rows (RESULT_COLUMNS) atomically: a reader never sees a half-written file."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=RESULT_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:  # free text (names, errors) cannot become a spreadsheet formula (OWASP)
        w.writerow({k: "" if r.get(k) is None else csv_cell(r.get(k)) if k in ("name", "error") else r.get(k)
                    for k in RESULT_COLUMNS})
    write_text(path, buf.getvalue())


def _done(row: dict | None) -> bool:
    if not row:
        return False
    return row.get("status") == "ok" and all(
        row.get(k) and os.path.exists(row[k]) for k in ("project", "mesh"))


@contextlib.contextmanager
def _quiet_dask() -> Any:
    """distributed's own loggers muted for the run: a worker that dies (killed, out of memory) makes the
    scheduler, nanny and client log a dozen lines and tracebacks; its job's row says it in one line."""
    names = ["distributed", *(n for n in list(logging.Logger.manager.loggerDict) if n.startswith("distributed."))]
    old = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.CRITICAL + 1)
    try:
        with warnings.catch_warnings():  # its HTTP server on another port when 8787 is taken: no matter here
            warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
            yield
    finally:
        for n, level in old.items():
            logging.getLogger(n).setLevel(level)


def _failed_row(j: Job, exc: BaseException) -> dict:
    """The one-line row of a job whose worker died or that could not be sent."""
    if type(exc).__name__ == "KilledWorker":
        msg = "the worker process running it died (killed, or out of memory?), on every retry"
    else:
        msg = f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"
    return {"job": j.key, "name": j.name, "series": j.series, "status": "failed", "error": msg}


@dataclass
class BatchResult:
    """``rows`` in manifest order; ``ran``, ``skipped``, ``failed`` counts; ``results`` path."""

    results: str
    rows: list[dict]
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return {"results": self.results, "jobs": len(self.rows), "ran": self.ran, "skipped": self.skipped,
                "failed": self.failed, "seconds": round(self.seconds, 3)}


def _client(scheduler: str | None, workers: int | None, processes: bool) -> tuple[Any, Any]:
    from distributed import Client, LocalCluster  # dask: seconds to import, only for a batch run

    if scheduler:
        if not str(scheduler).startswith(("tcp://", "tls://", "ucx://", "ws://", "wss://", "inproc://")):
            raise CtuiError(f"scheduler {scheduler!r}: want the address of a running Dask scheduler, "
                            "tcp://HOST:PORT", option="scheduler")
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise CtuiError(f"cannot reach the Dask scheduler at {scheduler} ({' '.join(str(exc).split())[:120]})") \
                from None
    extra = {"env": dict.fromkeys(SINGLE_THREAD_ENV, "1")} if processes else {}  # one core per job
    cluster = LocalCluster(n_workers=max(1, int(workers or 1)), threads_per_worker=1, processes=processes,
                           dashboard_address=None, silence_logs=logging.CRITICAL, **extra)
    return Client(cluster), cluster


def run_batch(manifest: str | os.PathLike, *, out: str | os.PathLike, scheduler: str | None = None,
              workers: int | None = None, processes: bool = True, progress: Progress | None = None,
              job_fn: Callable[[Job], dict] = run_job) -> BatchResult:
    """Run every job of ``manifest`` on Dask, writing ``out`` (RESULTS.csv) as jobs finish.

    ``scheduler``: "tcp://HOST:PORT" of a running dask.distributed scheduler; else a
    LocalCluster of ``workers`` (default 1) workers, processes unless ``processes=False``.
    """
    from distributed import as_completed

    t0 = time.perf_counter()
    out_s = os.fspath(out)
    default_outdir = str(Path(out_s).with_suffix("")) + "-outputs"
    jobs = read_manifest(manifest, default_outdir=default_outdir)
    if not jobs:
        raise CtuiError("the manifest holds no job", path=manifest)
    check_output(out_s, inputs=[manifest, *(j.series for j in jobs if j.series)], label="the results table")
    refuse_cross_writes(jobs)  # a row's outputs inside another row's series folder: that row fails, one line
    previous = read_results(out_s)
    rows: dict[int, dict] = {}
    todo = []
    for j in jobs:
        if _done(previous.get(j.key)):
            rows[j.row] = previous[j.key]
        else:
            todo.append(j)
    res = BatchResult(out_s, [], skipped=len(rows))

    def order() -> list[dict]:
        return [rows[j.row] for j in jobs if j.row in rows]

    write_results(out_s, order())
    report(progress, len(rows), len(jobs), f"{len(rows)} done before")
    last_write = time.perf_counter()
    if todo:
        with _quiet_dask():
            client, cluster = _client(scheduler, workers, processes)
            try:
                futures = {client.submit(job_fn, j, pure=False, key=f"ctui-job-{j.key}-{j.row}"): j for j in todo}
                for fut in as_completed(futures):
                    j = futures[fut]
                    try:
                        row = fut.result()
                    except Exception as exc:  # noqa: BLE001 - a worker died or the job could not be sent
                        row = _failed_row(j, exc)
                    rows[j.row] = row
                    res.ran += 1
                    res.failed += row.get("status") != "ok"
                    if time.perf_counter() - last_write >= WRITE_EVERY_S:  # not after every job: quadratic in rows
                        write_results(out_s, order())
                        last_write = time.perf_counter()
                    report(progress, len(rows), len(jobs), f"{j.name}: {row.get('status')}")
                write_results(out_s, order())
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    res.rows = order()
    res.seconds = time.perf_counter() - t0
    return res
