"""Reading input files within stated bounds: no file, however hostile, can hang rbp or exhaust
its memory.

Every reader of a user's file (scenario, planner configuration, plan, rig log, results file)
goes through `read_text`, and the YAML ones through `load_yaml`. The bounds (docs/formats.md):
- only regular files: a directory, a FIFO (which would block on open with no writer) or a
  device (`/dev/zero` never ends) is refused before it is opened for reading;
- at most `max_input_bytes()` bytes (8 MiB unless `RBP_MAX_INPUT_MB` says otherwise; four
  times that, `max_scan_bytes()`, for a drawing or scan to import), checked on the file's size
  and again while reading, so a file that grows cannot get past it;
- YAML of at most `max_input_values()` values (50,000 unless `RBP_MAX_INPUT_VALUES` says
  otherwise), counted on the parser's event stream before any tree is
  built (PyYAML's composed nodes take about 500 bytes each: a 60 MB file of `0,0,0,...` would
  need 9 GB), and whose aliases expand to at most that many values too (a few kB of nested
  aliases can expand to gigabytes once walked: the "billion laughs"; yaml.safe_dump writes
  aliases for shared objects, so they are not refused as such), nested at most MAX_DEPTH
  levels, with no scalar over MAX_SCALAR_CHARS characters nor a number over MAX_NUMBER_CHARS
  (Python refuses to convert an integer of more than 4,300 digits), without duplicate keys in
  a mapping (the last one would silently win);
- JSON of at most a quarter of the size limit in units (at least MAX_JSON_UNITS), counted: a value
  (after a `,`, `[` or `{`) one, a list one more, an object or key (`{`, `:`) five more, as a
  parsed object or key takes five times a number's memory (`json_units`).
A refusal raises InputFileError(field, reason); each reader turns it into its own error class,
so the user sees one line naming the file, the field (or "(file)") and the reason.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import sys
from pathlib import Path
from typing import Any

import yaml

from rb_drake.errors import RbpInputError

# A 300-phase plan is about 5 MB, the largest generated cave 0.3 MB. A near-limit file whose
# error is at its end is read whole: 32 MiB took 2 s and 200 MB, over the 1 s.
DEFAULT_MAX_INPUT_MB = 8.0
SCAN_FACTOR = 4  # drawings and scans to import: real cave scans are larger, read once
MAX_DEPTH = 64          # nesting levels: scenarios and plans use at most 8
# Values of a YAML document, aliases expanded, unless RBP_MAX_INPUT_VALUES says otherwise.
# PyYAML's tree and the checks cost about 6 us and 500 bytes a value, and `rbp plan` takes
# 0.6 s and 170 MB before it reads its scenario and configuration: with 50,000 values it
# refuses a bad one in 0.8-1.0 s and 195 MB (100,000: 1.2 s and 218 MB). Bundled caves:
# < 10,000; `rbp scenario generate`: about 23 an anchor, 5,000 for 30 m at 3 anchors a metre
# (it refuses a cave over the limit up front); `rbp scenario import`: 3 an outline vertex.
DEFAULT_MAX_NODES = 50_000
MAX_ALIASES = 10_000    # alias uses in a YAML document
MAX_SCALAR_CHARS = 1_000_000  # one YAML value: names and notes need a few hundred
MAX_NUMBER_CHARS = 4_000  # a YAML number's characters: below Python's 4,300-digit conversion limit
# Units of a JSON document (`json_units`), ~32 bytes parsed each: a quarter of the size limit's
# bytes, at least MAX_JSON_UNITS: a parse of 8x the limit (990,000 `{"a":0}` took 192 MB); rbp's
# plans count 0.12 a byte (a fixed 2 M refused a 24 MiB plan rbp wrote, whatever the limit).
MAX_JSON_UNITS = 2_000_000
JSON_OBJECT_UNITS = 5  # more for each `{` and `:`: a dict's 180 bytes, a key's pair and slot
# A YAML document's nodes are counted on its events (which need no tree) only when a cheap
# bound on them, from its structural characters, could exceed the limit, or it is long.
EVENT_COUNT_ABOVE_CHARS = 1_000_000

# libyaml's loader when PyYAML was built with it: 3 ms for a bundled cave instead of 22 ms.
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
MERGE_TAG = "tag:yaml.org,2002:merge"


class _Loader(SAFE_LOADER):  # type: ignore[valid-type,misc]
    """The safe loader, refusing (InputFileError naming the line) a value its constructor
    cannot build (`!!bool maybe`: KeyError; a long sexagesimal float: OverflowError) and an
    integer beyond a float's range: hex, octal, binary and sexagesimal forms build integers of
    thousands of digits from fewer characters, which no physical quantity needs and which
    crash `str()` or `float()` later."""

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        try:
            value = super().construct_object(node, deep)
        except (yaml.YAMLError, InputFileError, RecursionError):
            raise
        except Exception as e:  # any constructor failure is the file's fault
            raise InputFileError(_where(node.start_mark), f"not valid YAML: cannot read "
                                 f"{_short(node)} as {node.tag.rsplit(':', 1)[-1]} "
                                 f"({type(e).__name__})") from None
        if type(value) is int and not -sys.float_info.max <= value <= sys.float_info.max:
            raise InputFileError(_where(node.start_mark), "an integer beyond a float's range "
                                 f"(over {sys.float_info.max:.1e} in magnitude)")
        return value


# YAML 1.2 reads `1e308`, `1e-300`, `1.0e3` as floats, PyYAML's YAML 1.1 as strings (its floats
# need a dot and a signed exponent): `time_limit: 1e3` was "expected a number, got str".
# Integers (no exponent) stay integers; the readers range-check the float as any number.
_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?([0-9][0-9_]*(\.[0-9_]*)?|\.[0-9]+)"
                                         r"[eE][-+]?[0-9]+$"),
                              list("-+.0123456789"))


def _short(node: yaml.Node) -> str:
    text = repr(node.value) if isinstance(node, yaml.ScalarNode) else "this value"
    return text if len(text) <= 40 else text[:37] + "..."


class InputFileError(RbpInputError):
    """An input file refused before its content is interpreted: `field` ("(file)" for the
    file as a whole, "line L, column C" inside it) and `reason`; each reader adds the file."""

    def __init__(self, field: str, reason: str):
        super().__init__(reason, field=field)
        self.field: str = field


MAX_INPUT_MB = 1_000_000  # RBP_MAX_INPUT_MB's largest: about a terabyte
MAX_NODES = 10_000_000  # RBP_MAX_INPUT_VALUES's largest: PyYAML's tree of them takes ~5 GB


def max_input_bytes() -> int:
    """The size limit of an input file: RBP_MAX_INPUT_MB (megabytes above 0, at most
    MAX_INPUT_MB) if set, else 8 MiB. A malformed value is refused (RbpInputError naming the
    variable) rather than silently replaced by the default."""
    value = os.environ.get("RBP_MAX_INPUT_MB", "").strip()
    if not value:
        return int(DEFAULT_MAX_INPUT_MB * 2**20)
    try:
        megabytes = float(value)
    except ValueError:
        megabytes = math.nan
    if not 0 < megabytes <= MAX_INPUT_MB:  # nan and inf too
        raise RbpInputError(f"must be a number of megabytes above 0 and at most "
                            f"{MAX_INPUT_MB:,}, got {value!r}",
                            field="RBP_MAX_INPUT_MB (environment)")
    return max(1, int(megabytes * 2**20))


def max_scan_bytes() -> int:
    """The size limit of a drawing or scan that `rbp scenario import` reads: SCAN_FACTOR times
    `max_input_bytes()` (32 MiB by default)."""
    return SCAN_FACTOR * max_input_bytes()


def max_input_values() -> int:
    """The limit on a YAML document's values: RBP_MAX_INPUT_VALUES if set (a whole number from
    1 to MAX_NODES; a malformed one is refused naming the variable), else DEFAULT_MAX_NODES."""
    value = os.environ.get("RBP_MAX_INPUT_VALUES", "").strip()
    if not value:
        return DEFAULT_MAX_NODES
    try:
        number = float(value)  # "1e6" is taken; "1.5" is not a whole number
    except ValueError:
        number = math.nan
    if not (1 <= number <= MAX_NODES and number == int(number)):
        raise RbpInputError(f"must be a whole number of values from 1 to {MAX_NODES:,}, got "
                            f"{value!r}", field="RBP_MAX_INPUT_VALUES (environment)")
    return int(number)


def count_values(data: Any, stop_after: int | None = None) -> int:
    """The values (YAML nodes: keys, values and collections) `data` would be written as, as
    `load_yaml` counts them, for a writer to refuse a file rbp could not read back, or a reader
    a document already parsed; with `stop_after`, counting stops once past it (the count is
    then above it, not the whole)."""
    count, stack = 0, [data]
    while stack:
        value = stack.pop()
        count += 1
        if isinstance(value, dict):
            count += len(value)  # its keys
            stack.extend(value.values())
        elif isinstance(value, list | tuple):
            stack.extend(value)
        if stop_after is not None and count > stop_after:
            break
    return count


def _too_many(limit: int) -> str:
    return f"{limit:,} values (RBP_MAX_INPUT_VALUES raises the limit)"


def check_input_file(path: str | Path, max_bytes: int | None = None) -> int:
    """The byte limit an input file must keep to (default `max_input_bytes()`), once `path` is
    known to be a regular file within it; raises InputFileError("(file)", reason) otherwise
    (for readers that open the file themselves, such as an LCM log's)."""
    limit = max_input_bytes() if max_bytes is None else max_bytes
    try:
        # os.stat of the name as given: Path drops a trailing slash ("plan.json/" is no file)
        info = os.stat(path)  # follows symlinks; never blocks, unlike opening a FIFO
    except FileNotFoundError:
        # '-' is standard input to many tools: say that rbp reads files only
        stdin = " (rbp reads files, not standard input: ./- names a file called -)" \
            if str(path) == "-" else ""
        raise InputFileError("(file)", f"no such file{stdin}") from None
    except (OSError, ValueError) as e:  # a loop, a name too long or with a NUL byte, no access
        raise InputFileError("(file)", f"cannot read: {getattr(e, 'strerror', 0) or e}") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputFileError("(file)", "is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(info.st_mode)
                else "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode)
                else "a socket" if stat.S_ISSOCK(info.st_mode) else "not a regular file")
        raise InputFileError("(file)", f"is {kind}, not a regular file")
    if info.st_size > limit:
        raise InputFileError("(file)", f"is {_size(info.st_size)}, over the {_size(limit)} limit "
                             "for input files (RBP_MAX_INPUT_MB raises it)")
    return limit


def read_text(path: str | Path, max_bytes: int | None = None) -> str:
    """The UTF-8 text of a regular file of at most `max_bytes` (default `max_input_bytes()`);
    raises InputFileError("(file)", reason) for anything else."""
    data = read_bytes(path, max_bytes)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputFileError("(file)", f"not UTF-8 text (byte {e.start}): is this the right "
                             "file?") from None


def read_bytes(path: str | Path, max_bytes: int | None = None) -> bytes:
    """The bytes of a regular file of at most `max_bytes` (default `max_input_bytes()`);
    raises InputFileError("(file)", reason) for anything else."""
    limit = check_input_file(path, max_bytes)
    try:
        # O_NONBLOCK: should the path become a FIFO after the check, open returns at once
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise InputFileError("(file)", "is not a regular file")
            # at most the file's size + 1 bytes: read(limit + 1) allocated the whole limit
            # (RBP_MAX_INPUT_MB=100000: a MemoryError on every file)
            size = os.fstat(f.fileno()).st_size
            data = f.read(min(limit, size) + 1)
            if size < len(data) <= limit:  # it grew, or its size is not known (/proc): read on
                parts, total = [data], len(data)
                while total <= limit and (chunk := f.read(min(2**20, limit + 1 - total))):
                    parts.append(chunk)
                    total += len(chunk)
                data = b"".join(parts)
    except OSError as e:
        raise InputFileError("(file)", f"cannot read: {e.strerror or e}") from None
    if len(data) > limit:
        raise InputFileError("(file)", f"grew past the {_size(limit)} limit while being read")
    return data


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n} bytes"


def load_yaml(text: str) -> Any:
    """The one YAML document of `text`, refused (InputFileError naming the line and column) if
    it is not valid YAML, holds or expands (aliases included) to more than `max_input_values()`
    values,
    nests deeper than MAX_DEPTH, repeats a key in a mapping, or holds a value longer than
    MAX_SCALAR_CHARS or a number longer than MAX_NUMBER_CHARS, a value its constructor cannot
    build or an integer beyond a float's range (`_Loader`), or a merge key. A long document's
    values are counted on its events first (`_count_events`), before any tree is built."""
    limit = max_input_values()
    try:
        if len(text) > EVENT_COUNT_ABOVE_CHARS or _node_bound(text) > limit:
            _count_events(text, limit)
    except yaml.YAMLError as e:
        raise _yaml_error(e) from None
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_tree(node, limit)
        return _no_lone_surrogates(text, loader.construct_document(node))
    except yaml.YAMLError as e:
        raise _yaml_error(e) from None
    except RecursionError:  # the pure-Python parser, without libyaml's nesting limit
        raise InputFileError("(file)", f"nested deeper than {MAX_DEPTH} levels") from None
    finally:
        loader.dispose()


def _yaml_error(e: yaml.YAMLError) -> InputFileError:
    mark = getattr(e, "problem_mark", None)
    where = _where(mark) if mark else "(file)"
    problem = getattr(e, "problem", None) or " ".join(str(e).split())
    return InputFileError(where, f"not valid YAML: {problem}")


def _node_bound(text: str) -> int:
    """An upper bound on the nodes of a YAML document: every node but the root follows a
    structural character (a block entry's "-", a key's "?" or value's ":", a flow
    collection's "[", "{" or ","), and a flow mapping's "," can open a key and its empty
    value; so nodes <= 2 x those characters + 1 ("-" of a negative number only adds)."""
    return 2 * sum(text.count(c) for c in ",:-?[{") + 1


def _count_events(text: str, limit: int) -> None:
    """Refuse a YAML document with more than `limit` nodes (aliases counted once), nested
    deeper than MAX_DEPTH, or holding a scalar over MAX_SCALAR_CHARS characters, from the
    parser's events: constant memory, however large the document."""
    nodes = depth = 0
    for event in yaml.parse(text, Loader=SAFE_LOADER):
        if isinstance(event, yaml.ScalarEvent | yaml.AliasEvent | yaml.CollectionStartEvent):
            nodes += 1
            if nodes > limit:
                raise InputFileError(_where(event.start_mark), "holds more than "
                                     + _too_many(limit))
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > MAX_DEPTH:
                    raise InputFileError(_where(event.start_mark), f"nested deeper than "
                                         f"{MAX_DEPTH} levels")
            elif isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
                raise InputFileError(_where(event.start_mark), f"a value of "
                                     f"{len(event.value):,} characters (at most "
                                     f"{MAX_SCALAR_CHARS:,})")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def _where(mark: Any) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}"


def _check_tree(root: yaml.Node, limit: int) -> None:
    """Measure the composed document without expanding it: the composer shares one node for an
    anchor and its aliases, so each node's expanded size and height are computed once and
    reused, and the walk is linear in the file's size however large the expansion."""
    measured: dict[int, tuple[int, int]] = {}  # id(node) -> (values when expanded, height)
    open_nodes: set[int] = set()
    scalars: set[int] = set()  # id(node) of the scalars inside collections, checked once each
    reuses = 0

    def measure(node: yaml.Node, depth: int) -> tuple[int, int]:
        nonlocal reuses
        key = id(node)
        if key in measured:
            reuses += 1
            size, height = measured[key]
        elif key in open_nodes:
            raise InputFileError(_where(node.start_mark), "a YAML alias refers to a value "
                                 "that contains it: the document would be infinite")
        else:
            open_nodes.add(key)
            size, height = 1, 1
            children: list[yaml.Node] = []
            if isinstance(node, yaml.ScalarNode):
                _check_scalar(node)
            elif isinstance(node, yaml.MappingNode):
                _refuse_duplicate_keys(node)
                children = [n for pair in node.value for n in pair]
            elif isinstance(node, yaml.SequenceNode):
                children = list(node.value)
            for child in children:
                if type(child) is yaml.ScalarNode:  # most values: size and height 1, no call
                    if id(child) in scalars:  # an alias of an anchored scalar
                        reuses += 1
                    else:
                        scalars.add(id(child))
                        # long values (MAX_NUMBER_CHARS < MAX_SCALAR_CHARS) and numbers
                        if len(child.value) > MAX_NUMBER_CHARS or child.tag in _NUMBER_TAGS:
                            _check_scalar(child)
                    child_size, child_height = 1, 1
                else:
                    child_size, child_height = measure(child, depth + 1)
                size += child_size
                height = max(height, child_height + 1)
                if size > limit:
                    raise InputFileError(_where(node.start_mark), f"expands to more than "
                                         f"{limit:,} values through YAML aliases, if it has "
                                         "any (RBP_MAX_INPUT_VALUES raises the limit)")
            open_nodes.discard(key)
            measured[key] = (size, height)
        if depth + height - 1 > MAX_DEPTH:
            raise InputFileError(_where(node.start_mark), f"nested deeper than {MAX_DEPTH} "
                                 "levels")
        if reuses > MAX_ALIASES:
            raise InputFileError(_where(node.start_mark), f"uses more than {MAX_ALIASES:,} YAML "
                                 "aliases")
        return size, height

    measure(root, 1)


_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")
# A decimal integer (digits grouped by _ as PyYAML reads them: 1_000): YAML 1.1 (PyYAML's) also
# reads 0x10, 0b10, 010 (octal: 8) and 1:30 (sexagesimal: 90) as integers, which YAML 1.2
# reads otherwise (010 is 10, 1:30 a string), and an anchor id 0x10 became "16" without a word.
_PLAIN_INTEGER = re.compile(r"[-+]?(0|[1-9][0-9_]*)")


def _check_scalar(node: yaml.ScalarNode) -> None:
    if len(node.value) > MAX_SCALAR_CHARS:
        raise InputFileError(_where(node.start_mark), f"a value of {len(node.value):,} "
                             f"characters (at most {MAX_SCALAR_CHARS:,})")
    if not node.style and (  # plain, not quoted
            (node.tag == _NUMBER_TAGS[0] and not _PLAIN_INTEGER.fullmatch(node.value))
            or (node.tag == _NUMBER_TAGS[1] and ":" in node.value)):
        raise InputFileError(_where(node.start_mark), f"{node.value[:40]!r}: a number in "
                             "hexadecimal, octal, binary or sexagesimal, which YAML 1.1 and 1.2 "
                             "read differently; write numbers in decimal, and quote names")
    if node.tag in _NUMBER_TAGS and len(node.value) > MAX_NUMBER_CHARS:
        raise InputFileError(_where(node.start_mark), f"a number of {len(node.value):,} "
                             f"characters (at most {MAX_NUMBER_CHARS}): no physical quantity "
                             "needs so many digits")


def _refuse_duplicate_keys(node: yaml.MappingNode) -> None:
    keys: dict[tuple[str, str], yaml.Node] = {}
    for key, _ in node.value:
        if key.tag == MERGE_TAG:  # `<<:` can give a key twice, the merged one silently lost
            raise InputFileError(_where(key.start_mark), "a YAML merge key '<<' (no rbp file "
                                 "needs one): write the keys out")
        if isinstance(key, yaml.ScalarNode):
            name = (key.tag, key.value)
            if name in keys:
                first = keys[name].start_mark.line + 1
                raise InputFileError(_where(key.start_mark), f"duplicate key {key.value!r} "
                                     f"(first at line {first}): which one is meant?")
            keys[name] = key


def no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """json's `object_pairs_hook` that refuses a key repeated in an object (InputFileError)."""
    result: dict[str, Any] = {}
    for key, value in pairs:
        if key in result:
            raise InputFileError("(file)", f"duplicate key {key!r} in a JSON object: which one "
                                 "is meant?")
        result[key] = value
    return result


def json_units(text: str) -> int:
    """An upper bound on the memory JSON `text` takes parsed, in units of about 32 bytes (a
    number): every value but the first follows a `,`, `[` or `{` (one unit each), a list takes
    one unit more, an object or a key (each `{` and `:`) JSON_OBJECT_UNITS more. Characters
    inside strings only add, so the bound holds whatever the strings hold."""
    values = text.count(",") + text.count("[") + text.count("{") + 1
    return (values + text.count("[")
            + JSON_OBJECT_UNITS * (text.count("{") + text.count(":")))


def load_json(text: str, max_values: int | None = None, **options: Any) -> Any:
    """The JSON value of `text` (json.loads with `options`; a leading UTF-8 byte-order mark is
    skipped); refused (InputFileError) if its parse may take more than MAX_JSON_UNITS units
    (`json_units`, before any value is built), repeats a key in an object or holds an integer
    beyond a float's range (10**400 would raise OverflowError wherever it is used as a number;
    the field names its line); the caller handles json.JSONDecodeError and RecursionError.
    `max_values` also bounds its values, for a document of a smaller kind (a scenario inside a
    rig log holds at most what a scenario file may)."""
    text = text.removeprefix("\ufeff")
    units, most = json_units(text), max(MAX_JSON_UNITS, int(max_input_bytes() / 4))
    if units > most:
        raise InputFileError("(file)", f"too many values and objects to read: {units:,} units "
                             f"(a value 1, a list 2, an object or key {JSON_OBJECT_UNITS + 1}), "
                             f"over the limit of {most:,}")
    if max_values is not None and (bound := sum(text.count(c) for c in ",[{") + 1) > max_values:
        raise InputFileError("(file)", f"may hold up to {bound:,} values (its commas and "
                             f"brackets), over the limit of {max_values:,}")
    try:
        return _no_lone_surrogates(text, json.loads(
            text, object_pairs_hook=no_duplicate_keys, parse_int=_json_int, **options))
    except _HugeIntError as e:
        at = max(text.find(e.digits), 0)
        where = f"line {text.count(chr(10), 0, at) + 1}, column {at - text.rfind(chr(10), 0, at)}"
        raise InputFileError(where, "an integer beyond a float's range (over "
                             f"{sys.float_info.max:.1e} in magnitude)") from None
    except ValueError as e:
        if isinstance(e, json.JSONDecodeError | InputFileError):
            raise
        raise InputFileError("(file)", f"a number Python cannot convert: "
                             f"{' '.join(str(e).split())[:160]}") from None


class _HugeIntError(Exception):
    def __init__(self, digits: str):
        super().__init__(digits[:40])
        self.digits = digits


def _json_int(digits: str) -> int:
    # 309 digits reach 1e308; more cannot be a float (nor, past 4,300, be converted at all)
    value = int(digits) if len(digits) <= 310 else None
    if value is None or abs(value) > sys.float_info.max:
        raise _HugeIntError(digits)
    return value


# An escape of half a UTF-16 pair ("\ud800" in JSON, also "\U0000d800" in YAML): decoded, it
# is a lone surrogate, text no UTF-8 output can hold (a rig log's setup, a results file)
_SURROGATE_ESCAPE = re.compile(r"\\(?:u|U0000)[dD][89a-fA-F]")


def _no_lone_surrogates(text: str, data: Any) -> Any:
    """`data`, refused (InputFileError naming the field) if a key or string in it holds a lone
    surrogate; walked only when `text` has an escape that can make one."""
    if not _SURROGATE_ESCAPE.search(text):
        return data
    stack: list[tuple[Any, str]] = [(data, "")]
    while stack:
        value, where = stack.pop()
        children: list[tuple[Any, str]] = []
        if isinstance(value, dict):
            for key, item in value.items():
                field = f"{where}.{key}" if where else str(key)
                children += [(key, field), (item, field)]
        elif isinstance(value, list):
            children = [(item, f"{where}[{i}]") for i, item in enumerate(value)]
        elif isinstance(value, str) and not _encodable(value):
            raise InputFileError(where or "(file)", "a lone surrogate (a \\u escape of half "
                                 "a UTF-16 pair): not text UTF-8 can hold")
        stack.extend(reversed(children))  # the first in the document is named
    return data


def _encodable(text: str) -> bool:
    try:
        text.encode()
    except UnicodeEncodeError:
        return False
    return True
