"""Settings read from the environment, checked: a malformed value is one clear error naming
the variable, never a traceback from deep inside a search. Light to import (the command line
checks them before any work)."""

from __future__ import annotations

import os

from rb_drake.errors import RbpInputError

MAX_THREADS = 4096


def threads_setting() -> int | None:
    """RBP_THREADS as a whole number of threads from 1 to MAX_THREADS (None: not set)."""
    value = os.environ.get("RBP_THREADS", "").strip()
    if not value:
        return None
    try:
        threads = int(value)
    except ValueError:
        threads = 0
    if not 1 <= threads <= MAX_THREADS:
        raise _bad_threads("RBP_THREADS", value)
    return threads


def _bad_threads(variable: str, value: str, listed: bool = False) -> RbpInputError:
    """The refusal of a thread count (`listed`: a comma-separated list of them) from 1 to
    MAX_THREADS in environment variable `variable`."""
    what = " (or a comma-separated list of them)" if listed else ""
    return RbpInputError(f"must be a whole number of threads from 1 to {MAX_THREADS}{what}, "
                         f"got {value!r}", field=f"{variable} (environment)")


def threads_adapt_setting() -> bool:
    """RBP_THREADS_ADAPT: whether the kernels drop to the cores other processes leave free
    (`rb_drake.kernel.free_cores`; "1", the default) or always use every allowed thread ("0":
    for measuring a fixed thread count)."""
    value = os.environ.get("RBP_THREADS_ADAPT", "").strip()
    if value not in ("", "0", "1"):
        raise RbpInputError(f"must be 0 or 1, got {value!r}", field="RBP_THREADS_ADAPT "
                            "(environment)")
    return value != "0"


# numba's threading layers (NUMBA_THREADING_LAYER): another name ended in numba's traceback
NUMBA_LAYERS = ("default", "safe", "forksafe", "threadsafe", "tbb", "omp", "workqueue")
NUMBA_PRIORITY = ("tbb", "omp", "workqueue")  # NUMBA_THREADING_LAYER_PRIORITY's permutation
# numba's variables rbp reads or lets through (checked here, or a folder numba checks itself)
NUMBA_SUPPORTED = ("NUMBA_CACHE_DIR", "NUMBA_NUM_THREADS", "NUMBA_THREADING_LAYER",
                   "NUMBA_THREADING_LAYER_PRIORITY")


def _text_encoding() -> None:
    """Refuse a text encoding of ASCII (the C or POSIX locale with Python's UTF-8 mode turned
    off, PYTHONUTF8=0): pydrake reads its own files in it and its import ended in a
    UnicodeDecodeError, "ImportError: initialization failed" and 80 lines of traceback."""
    import codecs
    import locale
    import sys

    if sys.flags.utf8_mode or codecs.lookup(locale.getpreferredencoding(False)).name != "ascii":
        return
    off = os.environ.get("PYTHONUTF8") == "0"
    raise RbpInputError(
        "Python's text encoding is ASCII here (the C locale, Python's UTF-8 mode "
        f"{'turned off' if off else 'off'}), which Drake cannot start with: "
        + ("unset PYTHONUTF8 or set it to 1" if off else "run python with -X utf8")
        + ", or use a UTF-8 locale (LC_ALL=C.UTF-8)",
        field=f"{'PYTHONUTF8' if off else 'LC_ALL/LANG'} (environment)")


def library_settings() -> None:
    """Refuse (RbpInputError naming the variable) the libraries' variables that they would
    meet with a traceback (NUMBA_NUM_THREADS=0, NUMBA_THREADING_LAYER=nosuch) or a warning
    (NUMBA_NUM_THREADS=abc, OMP_NUM_THREADS=abc, printed twice by libgomp). The command line
    calls it before numba is imported; `import rbp` leaves the environment to the caller."""
    _text_encoding()
    numba_threads = os.environ.get("NUMBA_NUM_THREADS")
    if numba_threads is not None and not _whole_threads(numba_threads):
        raise _bad_threads("NUMBA_NUM_THREADS", numba_threads)
    omp = os.environ.get("OMP_NUM_THREADS")
    if omp is not None and not all(_whole_threads(part) for part in omp.split(",")):
        raise _bad_threads("OMP_NUM_THREADS", omp, listed=True)
    layer = os.environ.get("NUMBA_THREADING_LAYER")
    if layer is not None and layer not in NUMBA_LAYERS:
        raise RbpInputError(f"must be one of {', '.join(NUMBA_LAYERS)}, got {layer!r}",
                            field="NUMBA_THREADING_LAYER (environment)")
    if layer is not None:
        _layer_available(layer)
    priority = os.environ.get("NUMBA_THREADING_LAYER_PRIORITY")
    if priority is not None and sorted(priority.split()) != sorted(NUMBA_PRIORITY):
        raise RbpInputError(f"must list {', '.join(NUMBA_PRIORITY)} once each, in any order, "
                            f"separated by spaces, got {priority!r}",
                            field="NUMBA_THREADING_LAYER_PRIORITY (environment)")
    for name in sorted(os.environ):
        if name.startswith("NUMBA_") and name not in NUMBA_SUPPORTED:
            raise RbpInputError(
                # they change how the kernels compile or run: NUMBA_DISABLE_JIT=1 ran for
                # minutes, NUMBA_CPU_NAME recompiled every kernel, NUMBA_OPT=abc printed a
                # traceback as a warning
                f"not supported by rbp (it changes how rbp's compiled kernels build or run): "
                f"unset it; rbp lets through only {', '.join(NUMBA_SUPPORTED)}",
                field=f"{name} (environment)")
    _openmp_settings()
    if os.path.isfile(NUMBA_CONFIG_FILE):  # as numba looks for it, in the current folder
        raise RbpInputError(
            # numba applies its keys as NUMBA_* values at import, past the check above:
            # `opt: abc` printed a traceback-shaped warning, `disable_jit: 1` ran for minutes
            "numba's configuration file in the current folder, not supported by rbp (numba "
            "would apply its keys as NUMBA_* settings, which change how rbp's compiled "
            "kernels build or run): remove it or run rbp from another folder",
            field=NUMBA_CONFIG_FILE)


def _openmp_settings() -> None:
    """Refuse an OpenMP variable whose value libgomp would warn about ("libgomp: Invalid value
    for environment variable OMP_WAIT_POLICY", on every command that loads it, Drake's copy and
    numba's, before their output or error line): libgomp's own reading of the environment,
    caught as it loads here, so every variable and form it knows is judged as it judges them.
    What else it prints (OMP_DISPLAY_ENV's table) goes to stderr as before."""
    import ctypes
    import re
    import tempfile

    if not any(name.startswith(("OMP_", "GOMP_")) for name in os.environ):
        return
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to catch it on: left to libgomp
        return
    with tempfile.TemporaryFile() as caught:
        try:
            os.dup2(caught.fileno(), 2)
            try:
                ctypes.CDLL("libgomp.so.1")  # reads the variables as it loads, once a process
            except OSError:
                return  # not installed: the libraries bring their own, unchecked
            finally:
                os.dup2(saved, 2)
        finally:
            os.close(saved)
        caught.seek(0)
        text = caught.read(65536).decode("utf-8", "replace")
    found = re.search(r"libgomp: (\w+) value for envi\w* variable (\w+)", text)
    if found is None:
        if text:
            os.write(2, text.encode())
        return
    variable = found.group(2)
    raise RbpInputError(f"OpenMP (libgomp) finds its value {os.environ.get(variable, '')!r:.60} "
                        f"{found.group(1).lower()}: unset it or give one libgomp reads",
                        field=f"{variable} (environment)")


NUMBA_CONFIG_FILE = ".numba_config.yaml"  # numba reads it from the current folder at import
# the layers each NUMBA_THREADING_LAYER value may load (numba.np.ufunc.parallel): tbb, omp or
# workqueue; `default` and `forksafe` fall back to workqueue, which is always there
_LAYER_NEEDS = {"tbb": ("tbb",), "safe": ("tbb",), "threadsafe": ("tbb", "omp"),
                "omp": ("omp",)}


def _layer_available(layer: str) -> None:
    """Refuse a threading layer that numba cannot load here (TBB not installed): numba found
    out in the first parallel kernel, in a 77-line traceback. Loads the library numba would
    load, so no numba import."""
    needs = _LAYER_NEEDS.get(layer, ())
    if not needs or any(_loads(library) for library in needs):
        return
    what = " or ".join({"tbb": "Intel TBB (libtbb.so.12, 2021.6 or later)",
                        "omp": "OpenMP (libgomp.so.1)"}[n] for n in needs)
    raise RbpInputError(f"{layer!r} needs {what}, which is not installed here: unset it or "
                        "use default, forksafe or workqueue",
                        field="NUMBA_THREADING_LAYER (environment)")


def _loads(library: str) -> bool:
    """Whether numba's threading layer `library` (tbb or omp) can load: the shared library
    it needs opens (and TBB is the version numba asks for)."""
    import ctypes
    import sys

    if library == "omp" and sys.platform != "linux":
        return True  # numba's own check there (Intel OpenMP on macOS) is left to numba
    names = {"tbb": {"win32": "tbb12.dll", "darwin": "libtbb.12.dylib"}.get(
                 sys.platform, "libtbb.so.12"),
             "omp": "libgomp.so.1"}
    try:
        loaded = ctypes.CDLL(names[library])
        if library == "tbb":
            version = loaded.TBB_runtime_interface_version
            version.argtypes, version.restype = [], ctypes.c_int
            return bool(version() >= 12060)  # numba's own bound
    except (OSError, AttributeError):
        return False
    return True


def _whole_threads(value: str) -> bool:
    value = value.strip()
    return value.isdigit() and 1 <= int(value) <= MAX_THREADS


# Why matplotlib cannot start here (set by `quiet_matplotlib`), or None: no writable folder
# for its configuration and cache, and no temporary folder to make one in
MATPLOTLIB_PROBLEM: list[str] = []


def matplotlib_problem() -> str | None:
    """Why no picture can be drawn in this environment (`quiet_matplotlib` found no folder
    matplotlib can write), or None: a picture's output is refused with it before any work."""
    return MATPLOTLIB_PROBLEM[0] if MATPLOTLIB_PROBLEM else None


def quiet_matplotlib() -> None:
    """rbp draws only to files: the Agg backend whatever MPLBACKEND says (MPLBACKEND=nosuch
    ended in a traceback at import), and, when matplotlib's config or cache folder cannot be
    made (HOME a regular file), a fresh temporary MPLCONFIGDIR, silently: matplotlib printed
    two warning lines on every picture and before any error line."""
    import tempfile

    os.environ["MPLBACKEND"] = "Agg"
    home = os.path.expanduser("~")
    if os.environ.get("MPLCONFIGDIR"):
        folders = [os.environ["MPLCONFIGDIR"]]
    else:
        folders = [os.path.join(os.environ.get("XDG_CONFIG_HOME")
                                or os.path.join(home, ".config"), "matplotlib"),
                   os.path.join(os.environ.get("XDG_CACHE_HOME")
                                or os.path.join(home, ".cache"), "matplotlib")]
    for folder in folders:
        try:
            os.makedirs(folder, exist_ok=True)  # as matplotlib does
            usable = os.path.isdir(folder) and os.access(folder, os.W_OK | os.X_OK)
        except (OSError, ValueError):
            usable = False
        if not usable:
            try:
                fresh = tempfile.mkdtemp(prefix="rbp-matplotlib-")
            except OSError as e:  # no usable temporary folder either: this was a traceback
                # before any work, even of commands that draw nothing, and importing matplotlib
                # prints a warning and raises; a picture's output is refused (check_output)
                named = "MPLCONFIGDIR" if os.environ.get("MPLCONFIGDIR") else "HOME"
                MATPLOTLIB_PROBLEM[:] = [
                    f"no picture can be drawn here: matplotlib needs a writable folder, and "
                    f"neither {folder} ({named}) nor a temporary folder is one "
                    f"({e.strerror or e}); set MPLCONFIGDIR or TMPDIR to a writable folder"]
                return
            import atexit
            import shutil

            atexit.register(shutil.rmtree, fresh, ignore_errors=True)
            os.environ["MPLCONFIGDIR"] = fresh
            return


def standard_streams() -> None:
    """Make the standard output and error safe to print to, and a closed standard input
    the null device, once at start-up.

    A closed descriptor (`rbp ... >&-`, `2>&-`) leaves sys.stdout or sys.stderr None: the
    exit's flush ended in a traceback after the work was done, and the progress line's terminal
    test stopped `rbp plan` silently. The descriptor is reopened on the null device (so that no
    file rbp opens takes descriptor 1 or 2, where a library's C code would write into it) and
    the stream with it. Text that the stream's encoding cannot hold (a cave named `é洞` with
    PYTHONIOENCODING=ascii) is written as backslash escapes, as the error lines are, instead
    of ending a successful command in UnicodeEncodeError."""
    import sys

    try:  # a closed standard input (`<&-`, a daemon's): `rbp simulate --meshcat` ended in an
        os.fstat(0)  # AttributeError (sys.stdin None) after the simulation, and the first
    except OSError:  # file rbp opened took descriptor 0: read from the null device instead
        null = os.open(os.devnull, os.O_RDONLY)
        if null != 0:
            os.dup2(null, 0)
            os.close(null)
        sys.stdin = open(0, closefd=False)  # noqa: SIM115 (lives on)
    if sys.stdin is None:
        sys.stdin = open(os.devnull)  # noqa: SIM115 (lives on)
    for fd, name in ((1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
        except OSError:  # closed: take the lowest free descriptor, then move it to fd
            null = os.open(os.devnull, os.O_WRONLY)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            setattr(sys, name, open(fd, "w", closefd=False))  # noqa: SIM115 (lives on)
        stream = getattr(sys, name)
        if stream is None:
            setattr(sys, name, open(os.devnull, "w"))  # noqa: SIM115 (lives on)
        elif hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
