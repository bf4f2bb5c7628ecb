"""The errors rbp raises on purpose, and the exit statuses of its commands.

Every error of rbp's own derives from `RbpError`, so a caller can tell rbp's refusals from a
bug (a bare `ValueError` or `TypeError` from numpy, Drake or rbp's own invariants). A mistake in
the user's input (a scenario, a configuration, a plan file, a command-line value) is an
`RbpInputError`: it names the `file`, the `field` inside it and the `reason`, which is what the
command line prints on one line. `RbpInputError` is also a `ValueError`, as the errors it
gathers were before, so code that catches `ValueError` still catches them.

The exit statuses live here, in the lowest layer, so that the command line (`rbp/`) and the
experiment scripts (`experiments/`), which cannot import each other's modules, use the same
numbers. Only the standard library is imported: `rbp --help` stays instant.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final


class RbpError(Exception):
    """An error rbp raises on purpose (never a bug): the base of all of rbp's errors."""


class RbpInputError(RbpError, ValueError):
    """A mistake in the user's input: `file` (or another source, such as a command-line
    option), `field` (a dotted path inside it) and `reason`, each optional. The message is
    "file: field: reason" with the missing parts left out."""

    def __init__(self, reason: str, *, file: str | None = None, field: str | None = None):
        super().__init__(one_line(": ".join(part for part in (file, field, reason)
                                            if part is not None)))
        self.file = file
        self.field = field
        self.reason = reason


def one_line(text: str) -> str:
    """`text` with its control characters (newline, carriage return, escape, a Unicode line
    separator, ...) written as Python escapes: a file name, key or value holding them cannot
    break an error line in two or forge another `error:` line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def utf8_text(text: str) -> str:
    """`text` as UTF-8 can hold it: a file name's bytes that are not UTF-8, which Python holds
    as lone surrogates (`\udcff`), written as backslash escapes (as `one_line` prints them).
    For what rbp writes into a file from a path: a plan's `provenance.command` held the
    surrogate, and rbp's readers refuse it (`rbp check` refused the plan `rbp plan` had just
    written); `rbp scenario import` ended in a UnicodeEncodeError."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def apart(value: float, limit: float, decimals: int = 3) -> str:
    """`value` with `decimals` decimals, or as many more as it takes to read on its own side of
    `limit`: a value refused just past a limit is never printed as the limit itself, nor past
    it the other way (a probability of 0.99999999985 below p_min 0.9999999999 read "1.000")."""
    for places in range(decimals, 18):
        shown = float(text := f"{value:.{places}f}")
        if shown != limit and (shown < limit) == (value < limit):
            return text
    return repr(value)


def as_given(value: float) -> str:
    """`value` as `:g` writes it when that reads back as the same number, else in full (repr):
    a probability of 0.9999999999999999 is never printed as 1."""
    text = f"{value:g}"
    return text if float(text) == value else repr(float(value))


# The exit status of an rbp command or an experiment script (`rbp --help` lists them). Plain
# ints, as `sys.exit` and the tests compare them.
EXIT_OK: Final = 0           # done: a plan was found and written, a plan verified, ...
EXIT_FAILED: Final = 1       # ran, but no route / planning failed / the plan does not verify
EXIT_USAGE: Final = 2        # bad input (one line naming the file, field and reason), or an
#                              output that cannot be written
EXIT_INTERRUPTED: Final = 3  # Ctrl-C (or a closed output pipe): no traceback, no half-written file

# The largest seed any reader takes (--seed, a plan's provenance, a configuration, the
# experiments): numpy's generators take seeds 0 and up; rbp's stay in 64-bit integers
MAX_SEED: Final = 2**63 - 1


def key_text(key: object) -> str:
    """A mapping's key in a field's name as the file wrote it: YAML's null and booleans as
    `null`, `true` and `false` (they were named `None` and `True`), and an empty key or one
    with a dot or surrounding spaces quoted (`footstep.` named the key '')."""
    if key is None:
        return "null"
    if isinstance(key, bool):
        return "true" if key else "false"
    text = str(key)
    if not text or "." in text or text != text.strip():
        return repr(text)
    return text


def field_path(parts: Iterable[str | int]) -> str:
    """A field's path as every reader names it: names joined by dots, list indices in brackets
    (`phases[1].steps[0].pose[2]`, `anchors[3].id`)."""
    out = ""
    for part in parts:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out
