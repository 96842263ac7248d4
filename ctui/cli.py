"""ctui command line.

``ctui`` with no argument opens the TUI on the bundled sample series; ``ctui PATH`` or
``ctui open PATH`` opens any input :func:`ctui.engine.io.series.load` accepts.

Each subcommand lives in ``ctui/commands/<name>.py`` with ``register(subparsers)``
and ``run(args) -> int``; those modules import nothing heavy at top level, so
``ctui --help`` stays fast. User errors (:class:`ctui.engine.core.errors.CtuiError`) are
printed as one line on stderr with exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys

from ctui import __version__

OPEN_OPTIONS = ("--graphics", "--series", "--downsample", "--crop")  # options of `open` accepted without the command name
COMMANDS = ("open", "info", "demo", "segment", "edit", "drift", "mesh", "render", "measure", "export", "batch", "auto",
            "report", "web", "vessel")


def _command_modules() -> tuple:
    """The subcommand modules, in COMMANDS order (each imports nothing heavy at top level)."""
    from ctui.commands import auto, batch, demo, drift, edit, export, info, measure, mesh, open, render, segment
    from ctui.commands import report, vessel, web

    mods = {"open": open, "info": info, "demo": demo, "segment": segment, "edit": edit, "drift": drift, "mesh": mesh,
            "render": render, "measure": measure, "export": export, "batch": batch, "auto": auto,
            "report": report, "web": web, "vessel": vessel}
    return tuple(mods[name] for name in COMMANDS)


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as ONE line ``ctui CMD: <fault> (see ctui CMD --help)``, exit 2
    (the usage block is in --help); subcommand parsers are of this class too."""

    def error(self, message: str):  # type: ignore[override]  # argparse's error() is typed NoReturn; this one exits too, without the annotation
        from ctui.engine.core.safetext import printable

        self.exit(2, f"{self.prog}: {printable(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="ctui",
        description="Turn CT and MRI slice series into measured 3D models, from the terminal.",
        epilog="With no command, opens the TUI on the bundled sample series; `ctui PATH` opens PATH.",
    )
    parser.add_argument("--version", action="version", version=f"ctui {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        mod.register(sub)
    for name, sp in sub.choices.items():  # one privacy switch on every command that reports or writes
        if name != "open" and "--keep-identifiers" not in sp._option_string_actions:
            sp.add_argument("--keep-identifiers", action="store_true",
                            help="show the input's path in reports (folder names often carry the patient's "
                                 "name; default: shown as <input>)")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        argv = ["open"]
    elif argv[0] not in COMMANDS and (not argv[0].startswith("-") or argv[0].split("=")[0] in OPEN_OPTIONS):
        argv = ["open", *argv]  # `ctui PATH`, `ctui --graphics ascii [PATH]`
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    _quiet_libraries()
    from ctui.engine.core.limits import fit_address_space  # before numpy: BLAS reads its thread count at load

    fit_address_space()
    stdout = sys.stdout
    if stdout is None:  # started with stdout closed (`ctui info X >&-`)
        sys.stdout = stdout = open(os.devnull, "w")  # noqa: SIM115 - lives as long as the process
    if args.command != "open":
        _hide_input_paths(args, hide=not getattr(args, "keep_identifiers", False))
    ours = sys.stdout
    try:
        return _run(args)
    finally:
        if isinstance(ours, _PathHidingStdout) and sys.stdout is ours:  # only the stream this call set
            sys.stdout = stdout


def _memory_plan(args: argparse.Namespace) -> None:
    """A command about to load a series: refused in one line when its estimated peak will not
    fit (``actions.opened.memory_plan`` names what would); a volume render from an overview."""
    path = getattr(args, "path", None) or getattr(args, "input", None)
    if args.command not in ("segment", "mesh", "render", "auto", "drift") or getattr(args, "labels", None) or not path:
        return
    from ctui.commands.info import load_kwargs
    from ctui.engine.actions.opened import memory_plan
    from ctui.engine.core.errors import CtuiError

    volume = args.command == "render" and getattr(args, "mode", None) in (None, "mip", "minip", "dvr") \
        and getattr(args, "iso", None) is None
    plan = memory_plan(args.command, path, overview=volume, **load_kwargs(args))
    if plan.mode == "refuse":
        raise CtuiError(plan.reason, path=path[0] if isinstance(path, list) else path, option="memory")
    if plan.mode == "overview":
        args.downsample = ",".join([str(plan.downsample)] * 3)
        print(plan.summary(), file=sys.stderr)
    if plan.mode == "cache":  # the voxels memory-mapped from the cache file (io/voxcache)
        args.voxel_cache = True
        print(plan.summary(), file=sys.stderr)


def _run(args: argparse.Namespace) -> int:
    try:
        from ctui.engine.core.limits import check_address_space

        check_address_space(args.command)  # below it a library's loader crashes or spins (ulimit -v)
        _memory_plan(args)
        rc = args.func(args)
        sys.stdout.flush()  # a closed pipe shows up here, not at exit
    except BrokenPipeError:
        return _broken_pipe()
    except (Exception, KeyboardInterrupt) as exc:  # noqa: BLE001 - mapped below, or re-raised
        fault = error_line(exc)
        if fault is None:
            raise
        message, code = fault
        if code == 2:
            message = _naming_the_file(message, exc, args)
        from ctui.engine.core.safetext import printable

        _print_error(f"ctui {args.command}: {printable(message)}")
        return code
    return int(rc or 0)


def error_line(exc: BaseException) -> tuple[str, int] | None:
    """The one mapping from an error to the CLI's one-line message and exit status
    (None: a bug, shown as a traceback). CtuiError (user errors, from the engine and the
    commands; names the file and the fault) -> 2; Ctrl+C -> 130; out of memory and
    unwrapped OS errors -> 2."""
    from ctui.engine.core.errors import CtuiError

    if isinstance(exc, CtuiError):
        option = getattr(exc, "option", None)
        return (f"{exc} (see {flag_of(option)})" if option else str(exc)), 2
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted", 130
    if isinstance(exc, MemoryError):
        return "not enough memory for this input (MemoryError); try --crop or --downsample", 2
    if isinstance(exc, ImportError) and ".so" in str(exc):  # a library that cannot be mapped (ulimit -v, -n)
        return (f"cannot load a library ({' '.join(str(exc).split())[:120]}): the address-space or open-file "
                "limit (ulimit -v / -n) is too low for this command"), 2
    if isinstance(exc, OSError):  # an input or output the command did not wrap: still one line naming the file
        where = f"{exc.filename}: " if exc.filename else ""
        return " ".join(f"{where}{exc.strerror or exc}".split()), 2
    return None


#: Engine keywords whose CLI flag is not ``--`` + the keyword with ``-`` for ``_``.
FLAGS = {"threshold_mm": "--threshold", "objects": "--object", "slice_plane": "--slice", "step_mm": "--step",
         "average_mm": "--average", "section_step_mm": "--step"}


def flag_of(option: str) -> str:
    """The CLI flag of an engine action's keyword (``fit_window`` -> ``--fit-window``)."""
    return FLAGS.get(option, "--" + option.replace("_", "-"))


_PATH_ARGS = ("path", "input", "manifest", "out", "outdir", "project", "mask", "mric", "csv", "plot", "labels")


def _naming_the_file(msg: str, exc: BaseException, args: argparse.Namespace) -> str:
    """``msg`` prefixed with the command's input when it names no file (an engine check
    deep down, e.g. of a geometry field, does not know which file it came from)."""
    src = next((v for k in ("input", "path", "manifest") if (v := getattr(args, k, None))), None)
    if isinstance(src, list):
        src = src[0] if len(src) == 1 else None
    if not src or getattr(exc, "path", None) is not None or getattr(exc, "filename", None) or msg.startswith("-"):
        return msg
    named = [str(v) for k in _PATH_ARGS if isinstance(v := getattr(args, k, None), str) and v]
    if any(n in msg or os.path.basename(n.rstrip("/")) in msg for n in named):
        return msg
    return f"{src}: {msg}"


def _quiet_libraries() -> None:
    """Keep stderr to ctui's own one-line messages: library chatter (numpy RuntimeWarnings,
    nibabel's header-fix log lines) is hidden unless the user asks with -W/PYTHONWARNINGS
    or CTUI_DEBUG=1."""
    import logging
    import os
    import warnings

    if os.environ.get("CTUI_DEBUG"):
        return
    if not sys.warnoptions:
        warnings.simplefilter("ignore")
    for name in ("nibabel", "nibabel.global", "pydicom", "trimesh", "PIL", "numba"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _print_error(line: str) -> None:
    """The one error line on stderr (nothing when stderr is closed)."""
    if sys.stderr is None:  # started with stderr closed
        return
    try:
        print(line, file=sys.stderr)
    except (OSError, ValueError, AttributeError):
        pass


class _PathHidingStdout:
    """stdout with the command's input path(s) shown as ``<input>`` (reports only show the
    path when asked: --keep-identifiers) and every control character escaped (text from a
    file -- a DICOM description, a segment name -- cannot drive the terminal). Error
    messages on stderr still name the file."""

    def __init__(self, stream, hide) -> None:
        from ctui.engine.core.safetext import printable

        self._stream, self._hide = stream, hide
        self._safe = lambda t: printable(t, keep_newlines=True)

    def write(self, text: str) -> int:
        self._stream.write(self._safe(self._hide(text)))
        return len(text)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _hide_input_paths(args: argparse.Namespace, *, hide: bool = True) -> None:
    from ctui.engine.core.privacy import path_hider

    paths = [getattr(args, k, None) for k in ("path", "input")]
    sys.stdout = _PathHidingStdout(sys.stdout, path_hider(paths) if hide and any(paths) else (lambda t: t))


def _broken_pipe() -> int:
    """stdout's reader went away (``ctui ... --json | head``): stop quietly like other
    Unix tools, exit 141 (128 + SIGPIPE), and keep Python from complaining at exit."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
