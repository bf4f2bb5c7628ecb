"""argparse `type=` helpers that range-check a command-line option as it is read, so that
`rbp bench` and `rbp experiment` refuse a value that would allocate without bound or fail
late (a billion trials, a negative seed, a port beyond 65535) before any work, in argparse's
one `error:` line naming the option (docs/formats.md, "Command-line options")."""

from __future__ import annotations

import argparse
import ipaddress
import math
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from rb_drake.errors import EXIT_USAGE, MAX_SEED, one_line


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser with its usage errors in rbp's one line (`error: --trials: invalid
    whole number value: 'x' (see rbp experiment monte_carlo --help)`, exit status 2) instead
    of the usage block and `PROG: error: argument --trials: ...`; `--help` is unchanged. The
    main `rbp` parser, `rbp bench` and every experiment script's parser are of this class."""

    _innermost: OneLineParser | None = None  # the parser that ran last: the command's
    _given: tuple[str, ...] = ()  # this parser's arguments, for `_unknown_options`

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        # a subcommand's parser runs inside its parent's: the last one is the command's
        OneLineParser._innermost = self
        self._given = tuple(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def parse_args(self, args: Any = None, namespace: Any = None) -> Any:
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:  # named with the command's help (`rbp scenario check --bad` said `rbp`)
            (self._innermost or self).error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace

    def error(self, message: str) -> NoReturn:
        message = message.removeprefix("argument ")
        if message.startswith("the following arguments are required") and \
                (unknown := self._unknown_options()):
            # the mistake first (`rbp plan --bad` said -o was missing, `rbp --version` that
            # the command was)
            message = f"unrecognized arguments: {' '.join(unknown)}"
        if dashed := self._dashed_files():  # `rbp check -plan.json` said only "unrecognized"
            message += (f"; {dashed[0]}: a file name beginning with '-' is read as an option: "
                        f"write ./{dashed[0]}")
        self.exit(EXIT_USAGE, f"error: {one_line(message)} (see {self.prog} --help)\n")

    def _dashed_files(self) -> list[str]:
        """The arguments given that begin with '-' and name an existing file or folder, or
        look like a file's name (a '.' or '/' in a word that is no number: `-o -cave.yaml`)."""
        given = self._given[:self._given.index("--")] if "--" in self._given else self._given
        found = []
        for arg in given:
            if arg.startswith("-") and arg not in ("-", "--") and \
                    arg not in self._option_string_actions:
                named = ("." in arg or "/" in arg) and not _DECIMAL.fullmatch(arg) \
                    and not arg.startswith("--")
                try:
                    if named or os.path.lexists(arg):
                        found.append(arg)
                except ValueError:  # a NUL byte
                    pass
        return found

    def _unknown_options(self) -> list[str]:
        """The options given to this parser that it does not know (nor abbreviates)."""
        known = self._option_string_actions
        unknown = []
        for arg in self._given:
            if arg == "--":
                break
            name = arg.split("=", 1)[0]
            if not name.startswith("-") or name == "-" or name[1:2].isdigit() or \
                    name[1:2] == ".":
                continue
            if not (any(k.startswith(name) for k in known) if name.startswith("--")
                    else name[:2] in known):
                unknown.append(name)
        return unknown


_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(nan|inf|infinity)",
                      re.IGNORECASE | re.ASCII)


def decimal(text: str) -> float:
    """A number as a person writes it: Python's float() also reads "2_0" as 20 and
    full-width digits, which on a command line are typos, not numbers."""
    if not _DECIMAL.fullmatch(text.strip()):
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}")
    return float(text)


decimal.__name__ = "number"


def input_file(text: str) -> str:
    """A file's name as given; a name that ends with "/" after a file ("plan.json/") is refused
    here, since pathlib drops the slash and would read the file, and so is one that goes on
    after a file in any way the system refuses ("plan.json/.", which pathlib also reads as
    plan.json; "plan.json/.."): the system says "Not a directory"."""
    if text.endswith(("/", os.sep)) and os.path.exists(text.rstrip("/" + os.sep)) \
            and not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} ends with '/' but "
                                         f"{text.rstrip('/' + os.sep)!r} is a file, not a "
                                         "directory")
    try:
        os.stat(text)
    except NotADirectoryError:
        file = _file_on_the_way(text)
        raise argparse.ArgumentTypeError(f"{text!r} goes on after {file!r}, which is a file, "
                                         "not a directory") from None
    except (OSError, ValueError):
        pass  # missing, or another reason: the reader says which
    return text


def _file_on_the_way(text: str) -> str:
    """The first leading part of path `text` that is not a folder (what the system's "Not a
    directory" is about)."""
    parts = text.split(os.sep)
    for n in range(1, len(parts)):
        head = os.sep.join(parts[:n]) or os.sep
        if os.path.exists(head) and not os.path.isdir(head):
            return head
    return text


input_file.__name__ = "file name"


def path_name(text: str) -> str:
    """A file's or folder's name, not empty: `--out ''` was read as the current folder (a sweep
    wrote results.json there and its figure at /baseline.png) and `rbp bench --json ''` was
    ignored, as rbp's own commands refuse it (rbp.commands.common.refuse_empty_paths)."""
    if text == "":
        raise argparse.ArgumentTypeError("an empty path (''): give a file or folder name")
    return text


path_name.__name__ = "path"


def path_argument(text: str) -> Path:
    """`path_name` as a Path (pathlib reads '' as the current folder)."""
    return Path(path_name(text))


path_argument.__name__ = "path"


def whole(lo: int, hi: int) -> Callable[[str], int]:
    """A whole number from `lo` to `hi`."""
    def parse(text: str) -> int:
        try:
            value = int(text.strip())
            if not re.fullmatch(r"[+-]?\d+", text.strip(), re.ASCII):
                raise ValueError(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"must be a whole number from {lo:,} to {hi:,}, got {value:,}"[:200])
        return value
    parse.__name__ = "whole number"  # argparse's "invalid whole number value"
    return parse


def number(lo: float, hi: float) -> Callable[[str], float]:
    """A finite number from `lo` to `hi`."""
    def parse(text: str) -> float:
        value = decimal(text)
        if not (math.isfinite(value) and lo <= value <= hi):
            raise argparse.ArgumentTypeError(f"must be a number from {lo:g} to {hi:g}, "
                                             f"got {text!r}")
        return value
    parse.__name__ = "number"
    return parse


seed_number = whole(0, MAX_SEED)


def seed_list(text: str) -> list[int]:
    """Comma-separated seeds, each a whole number from 0 to MAX_SEED, none twice: an empty
    item, a word or a negative seed was a traceback (int() in the script, or in a worker's
    cave generator), and a seed given twice ran its cave twice."""
    seeds = [seed_number(item) for item in text.split(",")]  # "" refused as not a number
    if (twice := next((s for k, s in enumerate(seeds) if s in seeds[:k]), None)) is not None:
        raise argparse.ArgumentTypeError(f"seed {twice} given twice in {text[:80]!r}")
    return seeds


seed_list.__name__ = "seed list"

_HOST = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
                   r"(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$")


def tcp_address(text: str) -> str:
    """tcp://HOST:PORT with a host name or IP address and a port from 1 to 65535."""
    m = re.fullmatch(r"tcp://(\[[^\]]*\]|[^:/\[\]]*):(\d{1,5})", text.strip())
    if not m:
        raise argparse.ArgumentTypeError(f"must be tcp://HOST:PORT, got {text!r}")
    host, port = m.group(1), int(m.group(2))
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be from 1 to 65535, got {port}")
    bare = host.strip("[]")
    if host.startswith("[") or re.fullmatch(r"[\d.]+", bare):
        try:
            ipaddress.ip_address(bare)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{bare!r} is not an IP address") from None
    elif not _HOST.match(bare):
        raise argparse.ArgumentTypeError(f"{bare!r} is not a host name")
    return text.strip()


MAX_TRIALS = 100_000  # a sweep's trials: each is a record in memory and a file on disk
MAX_WORKERS = 1024
MAX_RUNS = 100_000  # stochastic executions per plan (monte_carlo, calibration)
MAX_EXPANSIONS = 10_000_000  # the footstep search's cap (FootstepConfig allows 1e9; minutes)


def json_type(value: Any) -> str:
    """The JSON name of `value`'s type, for a refusal."""
    names = {type(None): "null", bool: "a boolean", int: "a number", float: "a number",
             str: "a string", list: "a list", dict: "an object"}
    return names.get(type(value), type(value).__name__)


def read_json_file(path: str | Path, kind: type = dict) -> Any:
    """The JSON value (of type `kind`) of a file a user named, read within rbp's input bounds
    (rb_drake.input_files: a FIFO, a device, a directory, a huge file are refused unread);
    raises InputFileError(field, reason) for a file that is not such JSON."""
    import json

    from rb_drake.input_files import InputFileError, load_json, read_text

    try:
        value = load_json(read_text(path))
    except json.JSONDecodeError as e:
        raise InputFileError(f"line {e.lineno}, column {e.colno}", f"not JSON: {e.msg}") from None
    except RecursionError:
        raise InputFileError("(file)", "nested too deeply") from None
    if not isinstance(value, kind):
        names: dict[type, str] = {dict: "an object", list: "a list"}
        raise InputFileError("(file)", f"must be {names.get(kind, kind.__name__)}, got "
                             f"{json_type(value)}")
    return value


def json_argument(path: str | Path, kind: type = dict) -> Any:
    """`read_json_file` for a file named on a script's command line: a file that is not such
    JSON ends the script with one line, `error: FILE: FIELD: REASON` (escaped), exit status
    EXIT_USAGE."""
    from rb_drake.input_files import InputFileError

    try:
        return read_json_file(path, kind)
    except InputFileError as e:
        print(one_line(f"error: {path}: {e}"), file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
