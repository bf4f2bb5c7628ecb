"""numba's on-disk cache of the compiled kernels, stamped with every kernel source.

numba keys a compiled function's cache entry by its own file's content, but the cached code
also holds copies of the compiled functions it calls and the values of the globals it reads,
from whatever module: an edit to `allocation` would leave `pose_kernel.score_kernel`'s cached
code stale, and an edit to `pose_kernel` the lattice search's kernels in `planning/`. So the
kernels' entries are stamped instead with the contents of every module of this package, the
function's own file, and the values of the constants they read from other modules
(`_BAKED_CONSTANTS`: add any new one there): any edit to them recompiles every kernel, once.

A module outside this package whose njit functions call the kernel registers its file
(`stamp_with_kernel(__file__)`) before defining them. `install()` (run by the package's
`__init__`, before any kernel is defined) puts the stamping locators first in numba's list.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
from collections.abc import Callable, Iterator
from functools import lru_cache
from pathlib import Path
from typing import Any

try:
    import fcntl
except ImportError:  # not on POSIX: no lock (numba's own behaviour)
    fcntl = None  # type: ignore[assignment]

from numba.core import caching

from rb_drake.feasibility import Reason
from rb_drake.grasp import HALF_PI, INV_SQRT2, SQRT_2_OVER_PI
from rb_drake.params import NUM_BOOMS

KERNEL_DIR = Path(__file__).resolve().parent
_BAKED_CONSTANTS = (tuple((m.name, int(m)) for m in Reason), NUM_BOOMS, HALF_PI, INV_SQRT2,
                    SQRT_2_OVER_PI)
_CALLERS: set[Path] = set()


def stamp_with_kernel(py_file: str) -> None:
    """Stamp the cache entries of `py_file`'s compiled functions, which call the kernel, with
    the kernel's sources too (call it before they are defined)."""
    _CALLERS.add(Path(py_file).resolve())


def _is_stamped(py_file: str) -> bool:
    path = Path(py_file).resolve()
    return path.parent == KERNEL_DIR or path in _CALLERS


def source_stamp(py_file: str) -> bytes:
    """The stamp of `py_file`'s cache entries: its contents, the kernel package's and the
    constants the kernels read from other modules."""
    paths = sorted({*KERNEL_DIR.glob("*.py"), Path(py_file).resolve()})
    return _stamp(tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in paths))


@lru_cache(maxsize=64)
def _stamp(files: tuple[tuple[str, int, int], ...]) -> bytes:
    digest = hashlib.sha256(repr(_BAKED_CONSTANTS).encode())
    for path, _, _ in files:  # modification times and sizes key the memo only
        digest.update(path.encode())
        digest.update(Path(path).read_bytes())
    return digest.digest()


def _stamping(base: type) -> type[Any]:  # a subclass of base, which no static type names
    class Stamping(base):
        @classmethod
        def from_function(cls, py_func, py_file):  # numba calls it to choose a locator
            return super().from_function(py_func, py_file) if _is_stamped(py_file) else None

        def get_source_stamp(self) -> bytes:
            return source_stamp(self._py_file)

    Stamping.__name__ = Stamping.__qualname__ = f"Kernel{base.__name__}"
    return Stamping


LOCATORS = tuple(_stamping(base) for base in (
    caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
    caching.UserWideCacheLocator))


@contextlib.contextmanager
def _index_lock(cache_file: Any, exclusive: bool) -> Iterator[None]:
    """A lock on one function's cache index, shared between processes (flock on a file beside
    the index): none where the cache folder cannot hold one."""
    handle = None
    if fcntl is not None:
        with contextlib.suppress(OSError):
            handle = open(str(cache_file._index_path) + ".lock", "a+")  # noqa: SIM115
    try:
        if handle is not None:
            fcntl.flock(handle, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        yield
    finally:
        if handle is not None:
            handle.close()  # releases the lock


def _locked(method: Callable[..., Any], exclusive: bool) -> Callable[..., Any]:
    @functools.wraps(method)
    def locked(self: Any, *args: Any) -> Any:
        with _index_lock(self, exclusive):
            return method(self, *args)

    locked.__rbp_locked__ = True  # type: ignore[attr-defined]
    return locked


def _unreadable_is_missing(method: Callable[..., Any], missing: Any) -> Callable[..., Any]:
    """`method` (a cache file's read), with an entry or index that cannot be read taken as
    missing (`missing()`), so that the kernel is compiled again and saved over it: a truncated
    or garbled cache file (a disk that filled, a copy cut short) ended every command that
    plans in pickle's traceback ("pickle data was truncated") until the cache was deleted."""
    @functools.wraps(method)
    def tolerant(self: Any, *args: Any) -> Any:
        try:
            return method(self, *args)
        except Exception:  # whatever unpickling garbage raises: a cache miss
            return missing()

    tolerant.__rbp_tolerant__ = True  # type: ignore[attr-defined]
    return tolerant


def _unsaved_on_os_error(method: Callable[..., Any]) -> Callable[..., Any]:
    """`method` (a cache file's save), with an OSError (a full disk, a quota) leaving the
    entry unsaved: the kernel compiled in memory runs all the same. A full disk under the
    cache ended every planning command in "error: (file): No space left on device"."""
    @functools.wraps(method)
    def tolerant(self: Any, *args: Any) -> Any:
        try:
            return method(self, *args)
        except OSError:  # numba removes its own temporary file first
            return None

    tolerant.__rbp_unsaved__ = True  # type: ignore[attr-defined]
    return tolerant


def install() -> None:
    """Put the stamping locators first in numba's list, and make numba's cache files safe for
    several processes (once).

    numba saves an entry by reading the index, choosing a data file name, writing the index and
    then the data: two processes compiling different signatures of one function at the same
    time (a sweep's workers, a test's subprocess beside a user's run on a fresh cache) can both
    choose `.1.nbc`, and the index of one then names the other's code, which crashes the next
    process that loads it (a segmentation fault, seen in `rbp plan rig` after such a race).
    Saving under an exclusive lock and loading under a shared one, per function, rules it out.
    A cache file that cannot be read is a miss (`_unreadable_is_missing`)."""
    classes = caching.CacheImpl._locator_classes
    if not any(c in classes for c in LOCATORS):
        classes[:0] = LOCATORS
    cache_file = caching.IndexDataCacheFile
    if not getattr(cache_file._load_index, "__rbp_tolerant__", False):
        # numba's readers replaced on purpose (`_unreadable_is_missing`), which mypy refuses
        cache_file._load_index = _unreadable_is_missing(  # type: ignore[method-assign]
            cache_file._load_index, dict)
        cache_file.load = _unreadable_is_missing(  # type: ignore[method-assign]
            cache_file.load, lambda: None)
    if not getattr(cache_file.save, "__rbp_locked__", False):
        # numba's methods replaced on purpose (the docstring says why), which mypy refuses
        cache_file.save = _locked(  # type: ignore[method-assign]
            _unsaved_on_os_error(cache_file.save), exclusive=True)
        cache_file.load = _locked(cache_file.load, exclusive=False)  # type: ignore[method-assign]
