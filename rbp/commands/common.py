"""What the `rbp` commands share: the user's-mistake exception, reading a scenario argument,
reading a plan file, and refusing a plan that fails verification.

Only the standard library is imported at the top, so `rbp --help` stays instant; `rbp.cli` and
every module of `rbp.commands` import from here (never from `rbp.cli`, which imports them).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TextIO

from rb_drake.errors import EXIT_INTERRUPTED, MAX_SEED, RbpInputError, one_line
from rb_drake.files import MAX_DPI, MIN_DPI, remove_live_temporary


def plural(n: int, word: str) -> str:
    """'1 phase', '2 phases', '0 phases' (words whose plural adds an s)."""
    return f"{n} {word}{'' if n == 1 else 's'}"


class UserError(RbpInputError):
    """A mistake in the user's input: printed as one line, exit status 2 (`EXIT_USAGE`)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised as an interrupt (`clean_interrupts`)."""


HANGUPS = (signal.SIGTERM, signal.SIGHUP)  # the signals raised as `Terminated`


SWALLOWED_INTERRUPT_S = 5  # s after an interrupt: if the command has not unwound, it ends by force
IMPORT_POLL_S = 0.02  # s between looks at whether an interrupted import has finished
RECEIVED: list[int] = []  # the interrupting signals of this command (`clean_interrupts`)


def _importing(frame: Any) -> bool:
    """Whether `frame` runs inside an import: an interrupt raised there can leave a compiled
    library half-initialised (pydrake said "initialization failed", numba's extension raised
    ImportError, a segfault followed once), or be swallowed by an optional import's
    `except ImportError`."""
    seen = 0
    while frame is not None and seen < 500:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame, seen = frame.f_back, seen + 1
    return False


@contextlib.contextmanager
def clean_interrupts() -> Iterator[None]:
    """Within: Ctrl-C (SIGINT) raises KeyboardInterrupt and SIGTERM or SIGHUP (the terminal
    hung up) `Terminated` in the main thread, so that the command unwinds and an output's
    temporary file is removed (a killed picture write left a 0-byte .NAME.XXXX.tmp); an
    interrupt that arrives during an import is raised once the import is done; one that is
    swallowed, or a second one, ends the command within SWALLOWED_INTERRUPT_S with
    "interrupted" and status 3. A forked worker that inherits
    the handlers behaves as before (SIGTERM kills it, SIGINT raises KeyboardInterrupt). A
    SIGINT or SIGHUP that the caller ignores (a background job, nohup) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pid = os.getpid()
    received = RECEIVED
    received.clear()
    state = {"pending": False, "deadline": 0.0}

    def end_now(*_: object) -> None:
        """The interrupt was swallowed (raised inside a callback that Python only reports, as
        matplotlib's were while an animation was written), or came twice: end here, without
        the temporary files an output was being written to."""
        remove_live_temporary()
        with contextlib.suppress(OSError, ValueError):  # a hung-up terminal
            print("interrupted", file=sys.stderr, flush=True)
        os._exit(EXIT_INTERRUPTED)

    def interrupt() -> KeyboardInterrupt:
        return Terminated() if received[0] in HANGUPS else KeyboardInterrupt()

    def on_alarm(_signum: int, frame: Any) -> None:
        if time.monotonic() >= state["deadline"] or not state["pending"]:
            end_now()
        if _importing(frame):
            signal.setitimer(signal.ITIMER_REAL, IMPORT_POLL_S)
            return
        state["pending"] = False
        signal.setitimer(signal.ITIMER_REAL, max(0.01, state["deadline"] - time.monotonic()))
        raise interrupt()

    def handler(signum: int, frame: Any) -> None:
        if os.getpid() != pid:
            if signum == signal.SIGINT:
                signal.default_int_handler(signum, frame)
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        if received:
            end_now()
        received.append(signum)
        state["deadline"] = time.monotonic() + SWALLOWED_INTERRUPT_S
        signal.signal(signal.SIGALRM, on_alarm)
        if _importing(frame):
            state["pending"] = True
            signal.setitimer(signal.ITIMER_REAL, IMPORT_POLL_S)
            return
        signal.setitimer(signal.ITIMER_REAL, SWALLOWED_INTERRUPT_S)
        raise interrupt()

    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, handler)}
    for signum in (signal.SIGINT, signal.SIGHUP):  # a hang-up (the terminal closed) killed
        if signal.getsignal(signum) is not signal.SIG_IGN:  # rbp with its temporary file
            previous[signum] = signal.signal(signum, handler)  # left; nohup's stays ignored
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for signum, before in previous.items():
            signal.signal(signum, before)
        if received and sys.exc_info()[0] is None:
            raise interrupt()  # swallowed, and the command ended in time: still an interrupt




def check_seed(seed: int, flag: str = "--seed") -> None:
    """A seed within 0..MAX_SEED, or a UserError naming `flag` (a negative seed ended in
    numpy's traceback)."""
    if not 0 <= seed <= MAX_SEED:
        raise UserError(f"{flag}: must be 0 or more (at most 2**63 - 1), got {seed}")


def check_dpi(dpi: int) -> None:
    """A picture's --dpi within MIN_DPI..MAX_DPI (0 ended in matplotlib's traceback, 100000 in
    a MemoryError)."""
    if not MIN_DPI <= dpi <= MAX_DPI:
        raise UserError(f"--dpi: must be {MIN_DPI} to {MAX_DPI} dots per inch, got {dpi}")


def check_output(path: str | Path, flag: str = "-o", picture: bool | None = False,
                 animation: bool = False,
                 inputs: Mapping[str, str | Path | None] | None = None) -> Path:
    """`path` as an output of option `flag`, refused (UserError naming the user's path and
    `flag`, never a temporary file) before any work if it cannot be written: a folder, a device,
    a pipe (a symlink is followed), an unwritable place, a name too long for its temporary
    file, one of the command's `inputs` ({what: path}, e.g. {"the plan": args.plan}: `--json
    P.json P.json` replaced the plan), or another of the command's outputs (`--json X --html X`
    lost the JSON). An image suffix is refused for a data file (`picture` False), so that a
    plan and its picture never share a path; a picture's suffix must be a format matplotlib
    writes (an animation's writer is chosen by `check_animation`); `picture` None takes any
    suffix (an HTML page)."""
    from rb_drake.files import (
        IMAGE_SUFFIXES,
        output_problem,
        picture_format_problem,
        stream_descriptor,
    )

    given = str(path)  # named as given: Path drops a trailing "/"
    problem = output_problem(given, inputs)
    if problem is None and stream_descriptor(given) == 1:
        messages_to_stderr()  # `-o /dev/stdout >> FILE`: "wrote ..." followed the output
    path = Path(path)
    if problem is None and picture is False and path.suffix.lower() in IMAGE_SUFFIXES:
        problem = (f"is a picture's name; {flag} names the data file (its pictures are written "
                   "beside it, named after it)")
    if problem is None and picture:  # before matplotlib's import raises (no folder for it)
        from rb_drake.environment import matplotlib_problem

        problem = matplotlib_problem()
    if problem is None and picture and not animation:
        problem = picture_format_problem(path)
    key = os.path.realpath(path)  # missing files too, through the symlinks that exist
    if problem is None and _OUTPUTS.get(key, flag) != flag:
        problem = f"is also {_OUTPUTS[key]}'s output; give each output its own path"
    if problem is not None:
        raise UserError(f"{given}: {flag}: {problem}")
    _OUTPUTS[key] = flag
    return path


_OUTPUTS: dict[str, str] = {}  # this command's outputs checked so far: real path -> option


def output_flag(path: str | Path | None) -> str | None:
    """The option whose output `path` is (checked by `check_output`), or None."""
    return None if path is None else _OUTPUTS.get(os.path.realpath(path))


def forget_outputs() -> None:
    """Start a command: no output checked yet (`check_output`)."""
    _OUTPUTS.clear()
    restore_stdout()


_STDOUT: list[TextIO] = []  # standard output, while the messages go to stderr


def messages_to_stderr() -> None:
    """The command writes an output through standard output (`-o /dev/stdout > FILE`): its
    messages ("wrote ...") go to stderr from now on, so that they are not written into the
    output's file after it (`restore_stdout` ends this)."""
    if not _STDOUT:
        sys.stdout.flush()
        _STDOUT.append(sys.stdout)
        sys.stdout = sys.stderr


def restore_stdout() -> None:
    if _STDOUT:
        sys.stdout = _STDOUT.pop()


NOT_PATHS = {"name", "lcm_url"}  # the string arguments that do not name a file


def _path_options(parser: argparse.ArgumentParser, args: argparse.Namespace
                  ) -> Iterator[tuple[str, Any, bool]]:
    """(option name, value, whether an option) of each path argument of the command
    `args.func`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                if sub.get_default("func") is getattr(args, "func", None) or any(
                        isinstance(a, argparse._SubParsersAction) for a in sub._actions):
                    yield from _path_options(sub, args)
        elif (parser.get_default("func") is getattr(args, "func", None)
              and action.dest not in NOT_PATHS and action.choices is None):
            name = (action.option_strings[0] if action.option_strings
                    else f"{action.dest}: (argument)")
            yield name, getattr(args, action.dest, None), bool(action.option_strings)


def refuse_empty_paths(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse an empty path argument ('') of the command `args.func` (UserError naming the
    option): '' was read as `.` ("is a directory") and `--config ''` was silently ignored.
    With the current folder deleted, refuse its first relative path (an option's, or an
    argument that looks like a path, not a bundled cave's name) naming file and option: the
    OSError of os.getcwd() named neither."""
    paths = list(_path_options(parser, args))
    for name, value, _ in paths:
        if value == "":
            raise UserError(f"{name}: an empty path (''): give a file name")
    try:
        os.getcwd()
        return
    except OSError:
        pass
    for name, value, option in sorted(paths, key=lambda p: not p[2]):
        if isinstance(value, str | Path) and not os.path.isabs(value) and (
                option or os.sep in str(value) or "." in str(value)):
            raise UserError(f"{value}: {name}: the current folder no longer exists (deleted "
                            "while the shell was in it): give an absolute path or change folder")


def load_scenario_spec(spec: str, check_start: bool = True):
    """A scenario from a file path, or a bundled cave by name (see `rbp scenario list`):
    `rbp.api.load_scenario`."""
    from rbp.api import load_scenario

    return load_scenario(spec, check_start=check_start)


def read_plan(path: Path) -> dict:
    """A plan file, parsed and validated against the schema, NaN and Infinity refused; a user's
    mistake is a UserError naming the file, the field and the reason (shared by check, simulate
    and rig-run)."""
    from planning.plan_file import PlanFileError, read_plan_file

    try:
        return read_plan_file(path)
    except PlanFileError as e:
        raise UserError(f"{path}: {e}") from None


def cave_problems(plan: dict, spec: str) -> list[str]:
    """Rule `scenario` (`--scenario CAVE` of check, simulate and rig-run): what differs between
    the cave and robot `plan` embeds, which the verifier and the executors use (rig-run's
    clamps take the embedded robot's boom limits), and those of CAVE (a scenario file or a
    bundled cave's name); [] when the plan was made for CAVE."""
    from planning.plan_model import Plan
    from planning.verify_climb import scenario_problems

    scn = load_scenario_spec(spec, check_start=False)
    return [str(p) for p in scenario_problems(Plan.from_dict(plan), scn)]


def warn_unverified(path: Path) -> None:
    """--no-verify's warning, printed once the plan is read and accepted: a refusal stays one
    line (the warning came before the `error:` line)."""
    print(f"WARNING: {path}: --no-verify: using the plan WITHOUT verifying it; a wrong plan "
          "is executed as it is", file=sys.stderr)


def refuse_wrong_plan(plan: dict, path: Path, verify: bool = True,
                      executes: bool = False, scenario: str | None = None) -> bool:
    """Whether a consumer (simulate, rig-run) must refuse `plan`: it fails `rbp check`'s
    verifier, whose problems go to stderr. A plan stamped by `rbp check --stamp` and unchanged
    since is not verified again; `verify=False` (--no-verify) skips the check (the caller warns,
    `warn_unverified`, once the plan is accepted). `executes` (rig-run, which commands the
    straight motion between steps, and simulate, which follows it at minimum-jerk rates): a
    footstep plan's motion, which `rbp check` and its stamp leave unverified, must pass rule
    `between` too (`executed_motion_problems`). `scenario`
    (--scenario CAVE): the plan must have been made for CAVE's cave and robot (rule
    `scenario`, `cave_problems`), stamped, or with --no-verify, alike."""
    from planning.plan_file import has_valid_stamp

    if scenario is not None and (cave := cave_problems(plan, scenario)):
        for p in cave:
            print(one_line(f"error: {path}: {p}"), file=sys.stderr)
        print(one_line(f"error: {path}: the plan was not made for the cave and robot of "
                       f"{scenario}; refused"), file=sys.stderr)
        return True
    if not verify:
        from systems.trajectory import PlanError, check_flyable

        try:  # a plan that cannot become a trajectory, refused in one line even so
            check_flyable(plan)
        except PlanError as e:
            raise UserError(f"{path}: {e}") from None
        return False
    from rbp.progress import CheckProgress
    from systems.plan_check import executed_motion_problems, plan_problems

    problems: list[str] = []
    if not has_valid_stamp(plan):
        with CheckProgress(f"verifying {path}") as bar:
            problems, _ = plan_problems(plan, str(path), progress=bar)
    footstep = False
    if executes and not problems:
        problems = executed_motion_problems(plan, str(path))
        footstep = True
    for p in problems[:20]:
        print(one_line(f"error: {path}: {p}"), file=sys.stderr)
    if problems:
        count = plural(len(problems), "problem")
        shown = ", the first 20 shown above" if len(problems) > 20 else ""
        print(one_line(
            f"error: {path}: a footstep plan whose motion between steps, which rig-run "
            f"commands and simulate follows, fails rule between ({count}{shown}; rbp check "
            "verifies its end configurations only); refused: plan with motion (rbp plan without "
            "--footsteps-only)" if footstep else
            f"error: {path}: the plan fails verification ({count}{shown}); "
            f"refused (rbp check {path} lists them all)"), file=sys.stderr)
    return bool(problems)
