"""TotalSegmentator as the user installed it: found, checked, run as a subprocess, its output read.

ctui ships no model and downloads nothing. :func:`find` looks for the ``TotalSegmentator``
executable on PATH and for its weights where TotalSegmentator looks (``TOTALSEG_WEIGHTS_PATH``,
else ``TOTALSEG_HOME_DIR``/nnunet/results, else ``~/.totalsegmentator/nnunet/results``: its
``config.get_weights_dir``); licensed tasks (its ``map_to_binary.commercial_models``) need the
licence number TotalSegmentator keeps in ``config.json`` of that home folder. Each missing
piece is one line saying how to install it.

:func:`run` writes the series as a NIfTI (``io.labels.nifti_affine``: the affine ctui's own
label maps carry), calls ``TotalSegmentator -i IN.nii.gz -o OUT.nii.gz --ml --task T
[--roi_subset A B ...] [--fast] --device cpu|gpu`` and passes its output lines to the progress
callback. With ``--ml`` TotalSegmentator writes one label map whose NIfTI header extension holds
its class map (a CaretExtension XML ``LabelTable``: ``<Label Key="5" Red=".." Green=".."
Blue=".."><![CDATA[liver]]></Label>``, written by its ``nifti_ext_header.add_label_map_to_nifti``);
without it, one ``<class>.nii.gz`` per class in a folder. :func:`read_output` reads either.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import subprocess
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ctui.engine.core.errors import CtuiError
from ctui.engine.io.labels import load_labels, nifti_affine

EXECUTABLE = "TotalSegmentator"
INSTALL = "pip install TotalSegmentator (it brings torch), then totalseg_download_weights -t TASK"
POLL_S = 0.25  # the progress callback's period while TotalSegmentator prints nothing (a cancel is seen)
LICENCE_URL = "https://backend.totalsegmentator.com/license-academic/"
#: Tasks TotalSegmentator runs only with a licence number (its ``commercial_models``, 2.18).
LICENSED_TASKS = frozenset({
    "heartchambers_highres", "appendicular_bones", "appendicular_bones_mr", "tissue_types", "tissue_types_mr",
    "tissue_4_types", "face", "face_mr", "brain_structures", "thigh_shoulder_muscles", "thigh_shoulder_muscles_mr",
    "coronary_arteries", "coronary_arteries_LEGACY", "aortic_sinuses", "renal_arteries", "aorta_annulus",
    "aortic_dissection", "pulmonary_artery_landmarks"})
_LABEL = re.compile(r'<Label\s+Key="(\d+)"([^>]*)>\s*<!\[CDATA\[(.*?)\]\]>\s*</Label>', re.S)
_COLOUR = re.compile(r'(Red|Green|Blue)="([0-9.eE+-]+)"')


@dataclass
class Installation:
    """Where TotalSegmentator is: the executable, its home folder, its weights folder, its licence."""

    executable: str
    home: Path
    weights: Path
    licence: str = ""


@dataclass
class Classes:
    """A label map from TotalSegmentator: labels (nz, ny, nx) uint8 on the file's grid, its geometry
    Volume, and per label value its class name and colour (r, g, b 0..255, or None)."""

    labels: np.ndarray
    volume: Any
    names: dict[int, str] = field(default_factory=dict)
    colours: dict[int, tuple[int, int, int] | None] = field(default_factory=dict)


def home_dir() -> Path:
    """TotalSegmentator's home folder (``TOTALSEG_HOME_DIR``, else ``~/.totalsegmentator``)."""
    if os.environ.get("TOTALSEG_HOME_DIR"):
        return Path(os.environ["TOTALSEG_HOME_DIR"])
    home = Path("/tmp") if str(Path.home()) == "/" else Path.home()
    return home / ".totalsegmentator"


def weights_dir() -> Path:
    """Where TotalSegmentator keeps its weights (``TOTALSEG_WEIGHTS_PATH``, else HOME/nnunet/results)."""
    if os.environ.get("TOTALSEG_WEIGHTS_PATH"):
        return Path(os.environ["TOTALSEG_WEIGHTS_PATH"])
    return home_dir() / "nnunet" / "results"


def find(task: str) -> Installation:
    """The installation that can run ``task``; CtuiError (one line, how to install) for what is missing."""
    exe = shutil.which(EXECUTABLE)
    if exe is None:
        raise CtuiError(f"TotalSegmentator is not installed (no {EXECUTABLE} on PATH): {INSTALL.replace('TASK', task)}",
                        option="engine")
    weights = weights_dir()
    if not weights.is_dir() or not any(p.name.startswith("Dataset") for p in weights.iterdir()):
        raise CtuiError(f"TotalSegmentator has no weights in {weights}: run `totalseg_download_weights -t {task}` "
                        "where there is internet and copy the folder here (or set TOTALSEG_HOME_DIR / "
                        "TOTALSEG_WEIGHTS_PATH)", option="task")
    inst = Installation(exe, home_dir(), weights, _licence(home_dir()))
    if task in LICENSED_TASKS and not inst.licence:
        raise CtuiError(f"the TotalSegmentator task {task!r} is a licensed task (free for non-commercial use): get a "
                        f"licence at {LICENCE_URL} and run `totalseg_set_license -l YOUR_KEY`", option="task")
    return inst


def _licence(home: Path) -> str:
    try:
        cfg = json.loads((home / "config.json").read_text())
    except (OSError, ValueError):
        return ""
    lic = cfg.get("license_number") if isinstance(cfg, dict) else None
    return str(lic) if lic else ""


def write_input(path: Path, volume: Any) -> None:
    """The series as a NIfTI (values as they are: HU for CT; the affine of ctui's label maps)."""
    import nibabel as nib

    data = np.asarray(volume.data)
    if data.dtype not in (np.int16, np.uint8, np.float32):
        data = data.astype(np.float32)
    img = nib.Nifti1Image(np.ascontiguousarray(data.transpose(2, 1, 0)), nifti_affine(volume))
    img.set_qform(img.affine, code=1)
    img.set_sform(img.affine, code=1)
    nib.save(img, str(path))


def command(inst: Installation, src: Path, out: Path, *, task: str, roi_subset: Sequence[str] = (),
            fast: bool = False, device: str = "cpu") -> list[str]:
    """The command line: TotalSegmentator's own flags (``-i``, ``-o``, ``--ml``, ``--task``, ...)."""
    cmd = [inst.executable, "-i", str(src), "-o", str(out), "--ml", "--task", task, "--device", device]
    if roi_subset:
        cmd += ["--roi_subset", *roi_subset]
    if fast:
        cmd.append("--fast")
    return cmd


def run(cmd: list[str], *, progress: Callable[[str], bool | None] | None = None,
        env: dict[str, str] | None = None) -> list[str]:
    """Run ``cmd``, each output line to ``progress`` (returning False stops it: CtuiError "cancelled"; it
    is also called with "" every ``POLL_S`` seconds of silence, so a cancel is seen while the model loads);
    returns the output's last lines. A failure is one CtuiError with its last meaningful line. Whatever
    ``progress`` raises kills the process first."""
    tail: list[str] = []
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace",
                            env=env)
    assert proc.stdout is not None
    lines: queue.Queue[str | None] = queue.Queue()
    threading.Thread(target=_pump, args=(proc.stdout, lines), daemon=True, name="totalseg-output").start()
    try:
        while True:
            try:
                line = lines.get(timeout=POLL_S)
            except queue.Empty:
                line = ""
            if line is None:
                break
            text = line.strip()
            if text:
                tail = (tail + [text])[-20:]
            if progress is not None and (text or proc.poll() is None) and progress(text) is False:
                proc.kill()
                raise CtuiError("TotalSegmentator cancelled")
        code = proc.wait()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if code != 0:
        last = next((t for t in reversed(tail) if "error" in t.lower()), tail[-1] if tail else "no output")
        raise CtuiError(f"TotalSegmentator failed (exit {code}): {last[:300]}")
    return tail


def _pump(stream, lines: queue.Queue) -> None:
    """The process's output lines into ``lines``, then None."""
    try:
        for line in stream:
            lines.put(line)
    finally:
        lines.put(None)


def read_output(path: Path) -> Classes:
    """A ``--ml`` label map (names and colours from its header extension) or a folder of one NIfTI per
    class (names from the file names, label values in sorted name order)."""
    if path.is_dir():
        return _read_folder(path)
    labels, vol = load_labels(path)
    names, colours = class_map(path)
    for v in np.flatnonzero(np.bincount(labels.ravel(), minlength=256)[1:]) + 1:
        names.setdefault(int(v), f"label {int(v)}")
    return Classes(labels, vol, names, colours)


def class_map(path: Path) -> tuple[dict[int, str], dict[int, tuple[int, int, int] | None]]:
    """{value: class name}, {value: (r, g, b)} from a NIfTI's CaretExtension label table ({} when none)."""
    import nibabel as nib

    names: dict[int, str] = {}
    colours: dict[int, tuple[int, int, int] | None] = {}
    for ext in nib.load(str(path)).header.extensions:
        text = ext.get_content()
        text = text.decode("utf-8", "replace") if isinstance(text, bytes) else str(text)
        for key, attrs, name in _LABEL.findall(text):
            names[int(key)] = name.strip()
            rgb = dict(_COLOUR.findall(attrs))
            colours[int(key)] = (tuple(int(round(float(rgb[c]) * 255)) for c in ("Red", "Green", "Blue"))
                                 if len(rgb) == 3 else None)
    return names, colours


def _read_folder(path: Path) -> Classes:
    files = sorted(p for p in path.iterdir() if p.name.endswith((".nii.gz", ".nii")))
    if not files:
        raise CtuiError("TotalSegmentator wrote no NIfTI file", path=path)
    labels = vol = None
    names: dict[int, str] = {}
    for k, p in enumerate(files, start=1):
        if k > 255:
            raise CtuiError(f"{len(files)} classes: a label map holds at most 255", path=path)
        m, v = load_labels(p)
        if labels is None:
            labels, vol = np.zeros(m.shape, np.uint8), v
        elif m.shape != labels.shape:
            raise CtuiError(f"{p.name}: shape {m.shape} differs from the other classes' {labels.shape}", path=path)
        labels[m != 0] = k
        names[k] = p.name.split(".nii")[0]
    return Classes(labels, vol, names, {k: None for k in names})  # type: ignore[arg-type]  # no colours in TotalSegmentator's output: None takes the registry's colour
