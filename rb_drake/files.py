"""Atomic output: write to a temporary file beside the target, then rename over it.

An interrupted run therefore leaves either the old file or the complete new one, never half.
An existing output that has other names (reached through a symlink, or with hard links) or
another owner keeps its identity: once the new content is complete in the temporary file it
is copied into the file in place, as `cp` and editors do, so that every name sees it. An
output named by one of the process's own descriptors (`/dev/stdout` redirected to a file,
`/proc/self/fd/N`) is written through that descriptor (its offset: `>>` appends). Inside
`output_batch()` the last step of every write waits until the batch ends: a command's
outputs are all written, or (an error, a full disk, an interrupt) none is.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import signal
import stat
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

IMAGE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".gif", ".webp")
MIN_DPI, MAX_DPI = 20, 600  # a picture's resolution: 600 dpi draws a cave in ~100 M pixels


def output_target(path: str | Path) -> Path:
    """Where writing `path` lands: a symlink's target (the link stays a link), else `path`.
    Raises OSError for a symlink loop."""
    path = Path(path)
    if not path.is_symlink():
        return path
    try:
        return path.resolve(strict=False)
    except RuntimeError as e:  # Python 3.11 says "Symlink loop" with a RuntimeError
        raise OSError(f"{path}: a symlink loop") from e


TEMPORARY_EXTRA = 14  # atomic_write's temporary file is .NAME.XXXXXXXX.tmp: 14 bytes more


def output_problem(path: str | Path,
                   inputs: Mapping[str, str | Path | None] | None = None, *,
                   may_keep: bool = False) -> str | None:
    """Why `path` cannot be written as an output file, or None: checked before any work, so
    that a plan of minutes is not computed for nothing. A symlink is followed to its target; a
    missing folder is fine if it can be created. A name whose temporary file would exceed the
    folder's longest name is refused (it failed only after the work), and so is a path that is
    one of the command's `inputs` ({what: path}: the output would overwrite it). A name given
    as a string that ends with "/" is refused: pathlib drops the slash, and `-o plan.json/`
    wrote the file plan.json. An existing file its user may not write is refused too, unless
    `may_keep` (a sweep's finished trial record, kept as it is)."""
    if str(path) == "-":  # standard output to many tools: rbp wrote a file named '-'
        return "'-' is not standard output here: rbp writes files (./- names a file called -)"
    if (problem := descriptor_problem(path)) is not None:
        return problem
    try:
        target = output_target(path)
        # the given name stat-ed too: /dev/stdout, /proc/self/fd/N are links the kernel
        # follows to a pipe that resolving the name cannot reach ("cannot write a file there
        # (No such file or directory)")
        if (problem := _not_regular(Path(path)) or _not_regular(target)
                or (None if may_keep else _read_only(target))) is not None:
            return problem
        if isinstance(path, str) and path.endswith(("/", os.sep)):
            return "ends with '/', a folder's name: give a file name"
        if (problem := _dots_problem(str(path))) is not None:  # a Path keeps its ".."
            return problem
        folder = target.parent
        while not folder.exists() and folder != folder.parent:
            if folder.is_symlink():  # dangling: no folder can be made there ("error: link:
                return (f"its folder {folder} is a symlink to {os.readlink(folder)}, which "
                        "does not exist")  # File exists" after the work)
            folder = folder.parent  # the nearest existing folder must let us create the rest
    except RuntimeError:  # Python 3.11's symlink loop
        return "is a symlink loop"
    except OSError as e:  # a name too long, a loop, no permission on a folder on the way
        return "is a symlink loop" if e.errno == errno.ELOOP or e.errno is None else \
            f"cannot be written: {e.strerror}"
    if not folder.is_dir():
        return f"{folder} is not a folder"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"the folder {folder} is not writable"
    longest = _name_max(folder) - TEMPORARY_EXTRA
    if len(os.fsencode(target.name)) > longest:
        return (f"the file name is too long: {len(os.fsencode(target.name))} bytes, at most "
                f"{longest} here (its temporary file adds {TEMPORARY_EXTRA})")
    for what, given in (inputs or {}).items():
        if given is not None and _same_file(path, given):
            return f"is {what}; the output would overwrite it"
    if folder == target.parent:  # the mode says writable, but can a file be made there?
        try:  # (/proc/self/fd refused only after the work): make and remove one
            fd, tmp = _make_temporary(folder, target.name)
            os.close(fd)
            os.unlink(tmp)
        except OSError as e:
            return f"cannot write a file there ({e.strerror})"
    else:  # and can the missing folders be made in it? (-o /sys/kernel/x/plan.json and an
        try:  # experiment's --out under /sys failed only after the work, naming no option)
            os.rmdir(_make_temporary(folder, target.name, folder_too=True)[1])
        except OSError as e:
            return f"cannot make a folder in {folder} ({e.strerror})"
    return None


def _dots_problem(path: str) -> str | None:
    """Why a name with `.` or `..` parts cannot be an output as the system reads it, or None:
    pathlib drops a last `/.` (`-o cave.yaml/.` wrote cave.yaml, where the system says "Not a
    directory"), and a folder made for `x/../cave.yaml` (x missing: the system says "No such
    file or directory") was left behind, empty."""
    parts = path.split(os.sep)
    if parts[-1] in (".", ".."):
        return f"ends with '/{parts[-1]}', a folder's name: give a file name"
    for n, part in enumerate(parts[:-1]):
        if part == ".." and n > 0:
            head = os.sep.join(parts[:n]) or os.sep
            if not os.path.isdir(head):
                return (f"goes up out of {head} ('..'), which is not a folder: give the "
                        "file's name without it")
    return None


def _make_temporary(folder: Path, name: str, folder_too: bool = False) -> tuple[int, str]:
    """A new file (or, `folder_too`, folder) `.NAME.XXXXXXXX.tmp` in `folder`, as tempfile's
    mkstemp makes it (mode 0600, never an existing name): (its descriptor, -1 for a folder;
    its path). The path stays relative when `folder` is: tempfile makes it absolute, which
    fails past PATH_MAX, so that a current folder nested deeper than that (reached by relative
    `cd`s) refused every relative output, "cannot write a file there (File name too long)"."""
    for _ in range(100):
        tmp = os.path.join(folder, f".{name}.{secrets.token_hex(4)}.tmp")
        try:
            if folder_too:
                os.mkdir(tmp, 0o700)
                return -1, tmp
            return os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no unused temporary name", str(folder))


# The temporary files being written now: a process ended by force (`rbp`'s second SIGTERM,
# or its first when the interrupt was swallowed) removes them first
LIVE_TEMPORARY: set[str] = set()


def remove_live_temporary() -> None:
    """Remove every temporary file an `atomic_write` is still writing."""
    for tmp in list(LIVE_TEMPORARY):
        Path(tmp).unlink(missing_ok=True)
        LIVE_TEMPORARY.discard(tmp)


def _name_max(folder: Path) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _same_file(a: str | Path, b: str | Path) -> bool:
    """Whether paths `a` and `b` name one existing file (through symlinks and hard links)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either missing (b may be a bundled cave's name)
        return False


# names of this process's own descriptors: /dev/stdout, /dev/stderr, /dev/fd/N,
# /proc/self/fd/N, /proc/thread-self/fd/N, /proc/PID/fd/N
_DESCRIPTOR_NAME = re.compile(
    r"/dev/(?:(?P<std>stdin|stdout|stderr)|fd/(?P<dev>\d+))|"
    r"/proc/(?P<pid>self|thread-self|\d+)/fd/(?P<proc>\d+)")


def named_descriptor(path: str | Path) -> int | None:
    """The descriptor of this process that `path` names (`/dev/stdin`: 0, `/dev/stdout`: 1,
    `/proc/self/fd/3`: 3), or None."""
    found = _DESCRIPTOR_NAME.fullmatch(os.path.normpath(str(path)))
    if found is None:
        return None
    if found["pid"] not in (None, "self", "thread-self") and int(found["pid"]) != os.getpid():
        return None
    if found["std"]:
        return ("stdin", "stdout", "stderr").index(found["std"])
    return int(found["dev"] or found["proc"])


def _writable_descriptor(fd: int) -> bool:
    import fcntl  # a descriptor's name (/dev/stdout, /proc/self/fd/N) is a Unix one

    try:
        return fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE in (os.O_WRONLY, os.O_RDWR)
    except (OSError, OverflowError):
        return False


def descriptor_problem(path: str | Path) -> str | None:
    """Why `path`, a name of one of this process's descriptors, cannot be an output, or None:
    one open for reading only (`-o /dev/stdin < cave.yaml` replaced cave.yaml, the file given
    as the command's input)."""
    fd = named_descriptor(path)
    if fd is None:
        return None
    try:
        os.fstat(fd)
    except (OSError, OverflowError):
        return None  # not open: the name is what the system makes of it (no such file)
    if not _writable_descriptor(fd):
        which = "standard input" if fd == 0 else f"descriptor {fd}"
        return (f"names {which}, open for reading only: rbp would replace the file it reads "
                "from; give a file name")
    return None


def stream_descriptor(path: str | Path) -> int | None:
    """The descriptor of this process that `path` names (`/dev/stdout`: 1, `/proc/self/fd/3`:
    3) when it is open for writing on a regular file, else None. Such an output is written
    through the descriptor, at its offset: renaming over the file it resolves to replaced a
    file that `>>` appends to (its earlier contents lost), and what the command printed
    afterwards went to the replaced file."""
    fd = named_descriptor(path)
    if fd is None:
        return None
    try:
        regular = stat.S_ISREG(os.fstat(fd).st_mode)
    except (OSError, OverflowError):
        return None
    return fd if regular and _writable_descriptor(fd) else None


@dataclass
class _Pending:
    """A write whose temporary file is complete, waiting for its last step (`_finish`)."""

    tmp: str
    given: str
    target: Path
    how: str  # "rename", "in place" (other names see it), "stream" (an open descriptor)
    fd: int | None = None
    locked: int | None = None  # in place: the target, open and locked (`_lock`)


@dataclass
class OutputBatch:
    """The outputs of one `output_batch()`, finished together when it ends; `say(text)` is
    printed once they are (a callable is called then: a size read from the file written)."""

    pending: list[_Pending] = field(default_factory=list)
    messages: list[str | Callable[[], str]] = field(default_factory=list)

    def say(self, text: str | Callable[[], str]) -> None:
        self.messages.append(text)


_BATCHES: list[OutputBatch] = []


@contextlib.contextmanager
def output_batch() -> Iterator[OutputBatch]:
    """Write every output of the block, or none: each `atomic_write` inside it writes its
    temporary file and waits; when the block ends normally they are renamed (or copied, see
    `atomic_write`) one after the other with interrupts held, then the batch's messages are
    printed. An error or an interrupt inside the block removes every temporary file, so that
    no output is left (an earlier file of that name stays as it was): `rbp plan` on a full
    disk ended with `error: plan.png: ... No space left on device` and plan.json written."""
    batch = OutputBatch()
    _BATCHES.append(batch)
    try:
        yield batch
    except BaseException:
        _BATCHES.remove(batch)
        _discard(batch.pending)
        raise
    _BATCHES.remove(batch)
    try:  # waiting for another writer stays interruptible; the copies do not
        for pending in batch.pending:
            _lock(pending)
    except BaseException:
        _discard(batch.pending)
        raise
    with _interrupts_held():
        for n, pending in enumerate(batch.pending):
            try:
                _finish(pending)
            except BaseException:
                _discard(batch.pending[n:])
                raise
    from rb_drake.errors import one_line

    for message in batch.messages:  # a file name's newline forged an `error:` line
        print(one_line(message() if callable(message) else message))


def _discard(pending: list[_Pending]) -> None:
    for p in pending:
        Path(p.tmp).unlink(missing_ok=True)
        LIVE_TEMPORARY.discard(p.tmp)
        if p.locked is not None:
            os.close(p.locked)
            p.locked = None


def _lock(p: _Pending) -> None:
    """Open an in-place write's target and take an exclusive lock on it (`flock`: two rbp
    commands writing one file at once interleaved their copies; the rename needed none),
    waiting for another writer's turn before interrupts are held (`_interrupts_held`)."""
    if p.how != "in place" or p.locked is not None:
        return
    import fcntl  # Unix: hard links and symlinks are written in place there

    try:
        p.locked = os.open(p.target, os.O_WRONLY | os.O_CLOEXEC)
    except OSError as e:
        why = e.strerror or type(e).__name__
        raise OSError(e.errno, f"cannot write: {why}", p.given) from None
    with contextlib.suppress(OSError):  # a filesystem without locks: as before
        fcntl.flock(p.locked, fcntl.LOCK_EX)


@contextlib.contextmanager
def _interrupts_held() -> Iterator[None]:
    """Ctrl-C, SIGTERM and SIGHUP held until the block ends, then acted on as before: the
    last steps of a write (a copy in place, a batch's renames) are not cut in half."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    kept = {}
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        handler = signal.getsignal(sig)
        if handler in (signal.SIG_IGN, None):
            continue  # ignored (nohup) stays ignored
        kept[sig] = handler
        signal.signal(sig, lambda number, frame: arrived.append(number))
    try:
        yield
    finally:
        for sig, handler in kept.items():
            signal.signal(sig, handler)
        for number in arrived[:1]:
            handler = kept[signal.Signals(number)]
            if callable(handler):
                handler(number, None)
            else:  # SIG_DFL: as it would have been
                os.kill(os.getpid(), number)


def atomic_write(path: str | Path, write: Callable[[IO[bytes]], object]) -> Path:
    """Call `write(f)` on a temporary binary file, then rename it to `path` (to a symlink's
    target: the link stays). A target that exists and is not a regular file is refused
    (OSError naming `path`): renaming over it replaced a device such as /dev/zero, run as root,
    with a regular file, and a folder gave an error naming the temporary file. An existing
    target reached through a symlink, with other hard links or owned by another user is
    written in place once the temporary file is complete; a name of one of the process's own
    descriptors (`stream_descriptor`) through it. Inside `output_batch()` that last step waits
    for the batch's end."""
    given = path
    fd_out = stream_descriptor(given)
    path = output_target(path)
    if (problem := _not_regular(path)) is not None:
        raise OSError(errno.EEXIST, problem, str(given))
    if (problem := _read_only(path)) is not None:
        raise OSError(errno.EACCES, problem, str(given))
    how = "stream" if fd_out is not None else "in place" if _has_other_names(given, path) \
        else "rename"
    mode = _kept_mode(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = _make_temporary(path.parent, path.name)
    except OSError as e:  # name the output, not the temporary file (a folder such as /proc)
        why = e.strerror or (str(e.args[0]) if e.args else type(e).__name__)
        raise OSError(e.errno, f"cannot write a file there ({why})", str(path)) from None
    LIVE_TEMPORARY.add(tmp)
    pending = _Pending(tmp, str(given), path, how, fd_out)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, mode)  # made 0600: the replaced file's permissions, else the usual
        if _BATCHES:  # finished with the others, at the batch's end
            _BATCHES[-1].pending.append(pending)
            return path
        _lock(pending)
        with _interrupts_held():
            _finish(pending)
    except OSError as e:
        _discard([pending])
        if e.filename is not None or isinstance(e, BrokenPipeError):
            raise
        # a full disk: name the output (the error had no file: "error: : No space left")
        why = e.strerror or (str(e.args[0]) if e.args else type(e).__name__)
        raise OSError(e.errno, f"cannot write: {why}", str(given)) from None
    except BaseException:
        _discard([pending])
        raise
    return path


def _has_other_names(given: str | Path, target: Path) -> bool:
    """Whether the existing file `target` (reached by the name `given`) is known by other
    names (`given` is a symlink, or it has hard links) or belongs to another user: renaming a
    new file over it would leave those names on the old content (or change its owner)."""
    try:
        if Path(given).is_symlink():
            return target.exists()
        st = target.stat()
    except OSError:
        return False
    return stat.S_ISREG(st.st_mode) and (st.st_nlink > 1 or st.st_uid != os.geteuid())


def _finish(p: _Pending) -> None:
    """The last step of a write: rename the complete temporary file, or copy it into the file
    in place or through the descriptor; OSError (naming the output) leaves the file as it was
    (in place: the space is reserved before the file is touched; through a descriptor: cut
    back to where it was)."""
    try:
        if p.how == "rename":
            os.replace(p.tmp, p.target)
        elif p.how == "in place":
            _lock(p)
            assert p.locked is not None
            fd, p.locked = p.locked, None
            _copy_in_place(p.tmp, fd)
        else:
            assert p.fd is not None
            _copy_to_descriptor(p.tmp, p.fd)
    except OSError as e:
        if e.filename is not None or isinstance(e, BrokenPipeError):
            raise
        why = e.strerror or (str(e.args[0]) if e.args else type(e).__name__)
        raise OSError(e.errno, f"cannot write: {why}", p.given) from None
    finally:
        Path(p.tmp).unlink(missing_ok=True)
        LIVE_TEMPORARY.discard(p.tmp)


_CHUNK = 1 << 20


def _copy_in_place(tmp: str, fd: int) -> None:
    """Copy `tmp` into the file open (and locked) as `fd`, then close it."""
    size = os.path.getsize(tmp)
    try:
        old = os.fstat(fd).st_size
        if size > old and hasattr(os, "posix_fallocate"):
            try:  # the space first: a full disk refuses here, the file untouched
                os.posix_fallocate(fd, 0, size)
            except OSError as e:
                os.ftruncate(fd, old)
                if e.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                    raise
        _copy_into(tmp, fd)
        os.ftruncate(fd, size)
    finally:
        os.close(fd)


def _copy_to_descriptor(tmp: str, fd: int) -> None:
    import fcntl  # a descriptor's name (/dev/stdout, /proc/self/fd/N) is a Unix one

    for stream in (sys.stdout, sys.stderr):  # what was printed before comes first
        with contextlib.suppress(OSError, ValueError, AttributeError):
            stream.flush()
    appending = bool(fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_APPEND)
    start = os.fstat(fd).st_size if appending else os.lseek(fd, 0, os.SEEK_CUR)
    try:
        _copy_into(tmp, fd)
    except OSError:
        with contextlib.suppress(OSError):  # a full disk: the file as it was
            os.ftruncate(fd, start)
            os.lseek(fd, start, os.SEEK_SET)
        raise


def _copy_into(tmp: str, fd: int) -> None:
    """Write the whole of file `tmp` to `fd` at its offset, a chunk at a time."""
    with open(tmp, "rb") as src:
        while chunk := src.read(_CHUNK):
            view = memoryview(chunk)
            while view:
                view = view[os.write(fd, view):]


def _not_regular(target: Path) -> str | None:
    """Why `target` (a symlink already followed) cannot be replaced by an output, or None."""
    try:
        mode = target.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):  # not there yet (its folder is checked)
        return None
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory; give a file name"
    return "is not a regular file (a device or a pipe?); give a file name"


def _read_only(target: Path) -> str | None:
    """Why an existing `target` (a symlink already followed) must not be replaced, or None: a
    file its owner made read-only was replaced by the rename, which needs only its folder's
    permission (`cp` refuses; `rbp check --stamp` of a 0444 plan rewrote it 0644)."""
    try:
        if target.is_file() and not os.access(target, os.W_OK):
            mode = stat.S_IMODE(target.stat().st_mode)
            return (f"is read-only (mode {mode:04o}): rbp does not replace a file it may not "
                    "write; make it writable (chmod u+w) or give another name")
    except OSError:
        pass
    return None


def _kept_mode(target: Path) -> int:
    """The permissions an output gets: those of the file it replaces (a private 0600 plan
    became world-readable 0644 when written again), else the usual 0666 less the umask."""
    try:
        return stat.S_IMODE(target.stat().st_mode) & 0o777  # no set-id bits
    except OSError:
        return 0o666 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write(path, lambda f: f.write(text.encode()))


def picture_format_problem(path: str | Path) -> str | None:
    """Why matplotlib cannot write a picture named `path` (its suffix is no format of
    matplotlib's: .xyz ended in its ValueError after the work), or None; no suffix is PNG."""
    from matplotlib.backend_bases import FigureCanvasBase

    suffix = Path(path).suffix.lower().lstrip(".")
    formats = FigureCanvasBase.get_supported_filetypes()
    if not suffix or suffix in formats:
        return None
    return f"a picture's suffix must be one of {', '.join('.' + f for f in sorted(formats))}"


def atomic_save_figure(fig, path: str | Path, **kwargs) -> Path:
    """Save a matplotlib figure atomically; the format comes from the file's suffix."""
    fmt = Path(path).suffix.lower().lstrip(".") or "png"
    return atomic_write(path, lambda f: fig.savefig(f, format=fmt, **kwargs))
