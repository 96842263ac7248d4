"""Where the compiled (numba) kernels are cached, and whether they are compiled yet.

* :func:`configure_cache` (called by each kernel module): when ``NUMBA_CACHE_DIR`` is not
  set and the package's own ``__pycache__`` folders are not writable (a system-wide
  install), numba's cache goes to
  ``$XDG_CACHE_HOME/ctui/numba`` (default ``~/.cache/ctui/numba``), so the kernels are
  compiled once per user, not once per process.
* :func:`is_compiled` says whether a kernel is compiled in this process or loadable from
  the disk cache, without compiling it: the meshing functions use a vectorised numpy
  path meanwhile (same output), so a fresh install's first mesh takes about a second
  instead of 10-60 s of compilation.
* :func:`compile_in_background` compiles every kernel in a detached, low-priority
  process (once per 10 minutes at most), so the next command finds them compiled.

``CTUI_KERNELS=compiled`` (always compile and use the kernels), ``=numpy`` (always the
vectorised path) or ``=auto`` (default) chooses; ``CTUI_NO_BACKGROUND_COMPILE=1`` turns
the background compilation off.

numba itself is imported only by the kernel modules (``mc_kernels``, ``tool_kernels``,
``contour_tiling``, ``multilabel``), and those only when a kernel is about to run
(:func:`use_compiled` takes a function returning the kernels): importing numba costs
0.2-0.4 s per process and initialising its CPU target another 0.4-0.6 s, more than the
numpy path takes on a kidney or the sample. :func:`target_ready` says whether that price is
paid already in this process (one more cached kernel then loads in ~20 ms).
"""

from __future__ import annotations

import hashlib
import os
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Sequence


def _writable(folder: Path) -> bool:
    probe = folder if folder.exists() else folder.parent
    return os.access(probe, os.W_OK)


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/ctui/numba`` (``~/.cache/ctui/numba``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ctui" / "numba"


def configure_cache() -> str | None:
    """Point numba's cache at the user cache folder when the package folder is read-only;
    returns the folder in use (None: numba's default, next to the sources). Imports numba:
    the kernel modules call it before defining their ``cache=True`` kernels."""
    import numba

    if numba.config.CACHE_DIR:
        return str(numba.config.CACHE_DIR)
    if _writable(Path(__file__).resolve().parent / "__pycache__"):
        return None
    d = user_cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    numba.config.CACHE_DIR = str(d)
    return str(d)


def start_target() -> None:
    """Initialise numba's CPU target now, without its BLAS probe when that would import
    scipy.linalg only for it.

    On first use numba checks for BLAS by importing ``scipy.linalg.cython_blas``: 0.17-0.23 s
    of scipy.linalg and array-API imports, a third of numba's start-up. No ctui kernel uses
    BLAS (no ``np.dot``, ``@`` or ``np.linalg`` in a kernel); numba's linear-algebra functions
    import it themselves when a kernel using them is typed, so they still work. Done on the
    main thread only (the import is answered "absent" for the moment of the start-up, which
    another thread importing scipy.linalg at that moment would see)."""
    import threading

    name = "scipy.linalg.cython_blas"
    if target_ready() or name in sys.modules or threading.current_thread() is not threading.main_thread():
        return
    try:
        from numba.core.registry import cpu_target

        sys.modules[name] = None  # type: ignore[assignment]  # "import scipy.linalg.cython_blas" -> ImportError
        try:
            cpu_target.target_context.refresh()
        finally:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]
    except Exception:  # pragma: no cover - numba internals changed: its own start-up then
        pass


def _cache_dir_for_children() -> str | None:
    """The numba cache folder a background compilation should use, without importing numba."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return os.environ["NUMBA_CACHE_DIR"]
    nb = sys.modules.get("numba")
    if nb is not None and nb.config.CACHE_DIR:
        return str(nb.config.CACHE_DIR)
    if _writable(Path(__file__).resolve().parent / "__pycache__"):
        return None
    return str(user_cache_dir())


def target_ready() -> bool:
    """Whether numba's CPU target is initialised in this process (a kernel ran or was loaded):
    then one more cached kernel loads in milliseconds."""
    # the target's first refresh imports numba's numpy implementations (numba.np.arraymath)
    return "numba" in sys.modules and "numba.np.arraymath" in sys.modules


def mode() -> str:
    """'auto', 'compiled' or 'numpy' (``CTUI_KERNELS``)."""
    m = os.environ.get("CTUI_KERNELS", "auto").strip().lower()
    return m if m in ("auto", "compiled", "numpy") else "auto"


def is_compiled(dispatcher: Any, dtype: Any = None) -> bool:
    """Whether ``dispatcher`` (a numba kernel) has a version for data of ``dtype`` (its first
    argument; any when None) compiled in this process or in the disk cache. Looks at
    numba's cache index without compiling; when that cannot be read (another numba
    version), answers True (the compiled path, compiling if need be)."""
    try:
        import numba

        want = None if dtype is None else numba.from_dtype(dtype)

        def matches(sig) -> bool:
            if want is None:
                return True
            first = sig[0] if len(sig) else None
            return getattr(first, "dtype", None) == want

        if any(matches(s) for s in dispatcher.signatures):
            return True
        cache = getattr(dispatcher, "_cache", None)
        if cache is None:
            return False
        index = cache._cache_file._load_index()
        return any(matches(key[0]) for key in index)
    except Exception:  # pragma: no cover - numba internals changed
        return True


#: below this much work (voxels, faces) the vectorised numpy path is used unless the kernels
#: are already loaded in this process: importing numba, starting it and loading the cached
#: marching cubes costs ~0.5 s per process (1.2 s before numba was imported lazily and
#: started without its BLAS probe), more than the numpy path takes on small input (a
#: kidney's 9 k-face mesh: `ctui mesh` 2.6 -> 1.4 s CPU; the sample's isosurface 2.3 -> 1.8 s)
SMALL_WORK = 4_000_000


def cache_lacks(module: str, names: Sequence[str]) -> bool:
    """True when numba's disk cache surely holds no compiled version of one of the kernels
    ``names`` of ``ctui/engine/mesh/<module>.py``: its index file
    (``<module>.<name>-<line>.pyXY.nbi``) is in none of the folders numba would read (its
    ``NUMBA_CACHE_DIR`` subfolder, else the package's ``__pycache__`` or the user cache of
    :func:`configure_cache`). Answered without importing numba (0.25 s), so that a cold cache
    does not pay for numba only to learn that nothing is compiled; False once numba is
    imported (it answers itself, cheaply)."""
    if "numba" in sys.modules:
        return False
    here = os.path.dirname(os.path.abspath(__file__))  # the kernels' folder, as numba names it
    sub = f"{os.path.basename(here)}_{hashlib.sha1(here.encode()).hexdigest()}"
    env = os.environ.get("NUMBA_CACHE_DIR")
    folders = [Path(env) / sub] if env else [Path(here) / "__pycache__", user_cache_dir() / sub]
    tag = f"py{sys.version_info[0]}{sys.version_info[1]}"
    folders = [f for f in folders if f.is_dir()]
    return not all(any(any(f.glob(f"{module}.{name}-*.{tag}.nbi")) for f in folders) for name in names)


def use_compiled(dispatchers: Sequence[Any] | Callable[[], Sequence[Any]], dtype: Any = None, *,
                 work: int | None = None, cheap_when_ready: bool = False,
                 cached_in: tuple[str, Sequence[str]] | None = None) -> bool:
    """Whether to run the compiled kernels (all of ``dispatchers`` ready, or forced).

    ``dispatchers``: the kernels, or a function returning them (called only when the
    answer needs them, so numba is not imported for small jobs). ``work`` (voxels or
    faces): small jobs take the numpy path in ``auto`` mode unless every kernel is
    already loaded in this process, or (``cheap_when_ready``) numba's target is initialised
    and the kernels are in the disk cache (same output either way). ``cached_in``: (module,
    kernel names) for :func:`cache_lacks`: when the disk cache surely lacks one, the answer is
    False without importing numba."""
    m = mode()
    if m != "auto":
        if m == "compiled":
            start_target()
        return m == "compiled"
    if cached_in is not None and cache_lacks(*cached_in):
        return False
    small = work is not None and work < SMALL_WORK and not (cheap_when_ready and target_ready())
    if small and "numba" not in sys.modules:  # no kernel can be loaded in this process yet
        return False
    ds = dispatchers() if callable(dispatchers) else dispatchers
    if small and not all(getattr(d, "signatures", None) for d in ds):
        return False
    if all(is_compiled(d, dtype) for d in ds):
        start_target()
        return True
    return False


_LOCK = Path(tempfile.gettempdir()) / f"ctui-numba-warm-{os.getuid() if hasattr(os, 'getuid') else 0}.lock"
_spawned = False


def _take_lock() -> bool:
    """Stamp the once-per-10-minutes lock in ``$TMPDIR``; False when it is fresh, or is not this
    user's own regular file (a symlink planted there was followed and its target overwritten:
    opened with O_NOFOLLOW, never through a link)."""
    try:
        st = os.lstat(_LOCK)
    except FileNotFoundError:
        st = None
    if st is not None:
        if not stat.S_ISREG(st.st_mode) or (hasattr(os, "getuid") and st.st_uid != os.getuid()):
            return False
        if time.time() - st.st_mtime < 600:
            return False
    fd = os.open(_LOCK, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0), 0o600)
    try:
        os.write(fd, str(os.getpid()).encode())
    finally:
        os.close(fd)
    return True


def compile_in_background() -> bool:
    """Start ``python -m ctui.engine.mesh.warm`` detached at low priority (at most once per
    process and once per 10 minutes per user); True when started."""
    global _spawned
    if _spawned or os.environ.get("CTUI_NO_BACKGROUND_COMPILE") or mode() == "numpy":
        return False
    _spawned = True
    try:
        if not _take_lock():
            return False
        kw: dict[str, Any] = {"stdin": subprocess.DEVNULL, "stdout": subprocess.DEVNULL,
                              "stderr": subprocess.DEVNULL, "close_fds": True}
        if os.name == "posix":
            kw["start_new_session"] = True
            kw["preexec_fn"] = lambda: os.nice(19)
        env = dict(os.environ, CTUI_NO_BACKGROUND_COMPILE="1")
        cache_dir = _cache_dir_for_children()
        if cache_dir:
            env["NUMBA_CACHE_DIR"] = cache_dir
        subprocess.Popen([sys.executable, "-m", "ctui.engine.mesh.warm"], env=env, **kw)
        return True
    except OSError:
        return False
