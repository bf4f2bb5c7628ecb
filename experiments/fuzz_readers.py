"""Fuzzing the readers: hostile documents: random mutations of valid scenarios, configurations and
plans (types, structure, extreme numbers, huge strings, unicode), shared by the test suite's
small run (`tests/test_fuzz_readers.py`) and the benchmark-size one
(`python -m experiments.fuzz_readers`).

A reader passes when every document is accepted or refused with the reader's own error (an
`RbpInputError`, whose message names the file, the field and the reason on one line): never
another exception, which would reach the user as a traceback.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from experiments.arguments import OneLineParser, seed_number, whole

# Values a field may be replaced by: extreme and awkward numbers, wrong types, big structures.
HOSTILE_VALUES: tuple[Any, ...] = (
    0, -0.0, 1, -1, 0.5, 1e-308, 5e-324, -5e-324, 1e308, -1e308, math.inf, -math.inf, math.nan,
    2**64, -(2**64), 10**400, True, False, None, "", "x" * 10_000, "\u00e9\u4e2d\U0001f600",
    "\x00\n\r", [], {}, [[]], [1, 2, 3], [1e308, -1e308], {"a": 1}, [None] * 4, ["a"] * 4,
    [0.0, 0.0], [0.0, 0.0, 0.0], [[0.0, 0.0]] * 3, list(range(100)),
)


def _paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to a value inside nested dicts and lists."""
    out = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            out.extend(_paths(item, (*prefix, key)))
    elif isinstance(value, list):
        for k, item in enumerate(value):
            out.extend(_paths(item, (*prefix, k)))
    return out


def mutate(document: Any, rng: np.random.Generator, edits: int = 3) -> Any:
    """A copy of `document` with `edits` random edits: a value replaced by a hostile one, a key
    removed or added, a list emptied, duplicated or cut."""
    doc = copy.deepcopy(document)
    for _ in range(edits):
        paths = _paths(doc)
        path = paths[int(rng.integers(len(paths)))]
        if not path:
            if rng.random() < 0.2:
                doc = HOSTILE_VALUES[int(rng.integers(len(HOSTILE_VALUES)))]
            continue
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        key = path[-1]
        action = rng.random()
        value = HOSTILE_VALUES[int(rng.integers(len(HOSTILE_VALUES)))]
        if action < 0.6:
            parent[key] = copy.deepcopy(value)
        elif action < 0.75 and isinstance(parent, dict):
            del parent[key]
        elif action < 0.85 and isinstance(parent, dict):
            parent[f"extra{int(rng.integers(100))}"] = copy.deepcopy(value)
        elif isinstance(parent[key], list):
            items = parent[key]
            parent[key] = (items[: int(rng.integers(len(items) + 1))] if rng.random() < 0.5
                           else items + items)
        else:
            parent[key] = copy.deepcopy(value)
    return doc


def run_reader(read: Callable[[Any], Any], documents: list[Any],
               accepted_errors: tuple[type[BaseException], ...]) -> list[tuple[int, str]]:
    """`read` each document; the (index, exception) of those that raised anything but
    `accepted_errors` (each of which must have a one-line message)."""
    failures = []
    for k, doc in enumerate(documents):
        try:
            read(doc)
        except accepted_errors as e:
            if "\n" in str(e):
                failures.append((k, f"a message of several lines: {str(e)[:200]!r}"))
        except Exception as e:  # anything else would reach the user as a traceback
            failures.append((k, f"{type(e).__name__}: {str(e)[:200]}"))
    return failures


def scenario_reader() -> tuple[Any, Callable[[Any], Any], tuple[type[BaseException], ...]]:
    """The demo cave's document, a reader of mutated ones (as `rbp scenario check` reads a
    file: the start pose checked too) and its error."""
    import yaml

    from rb_drake.scenario import ScenarioError, bundled_caves, scenario_from_dict

    base = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    return base, lambda doc: scenario_from_dict(doc, "fuzz.yaml"), (ScenarioError,)


def config_reader() -> tuple[Any, Callable[[Any], Any], tuple[type[BaseException], ...]]:
    """A planner configuration (every field, as a plan's provenance records it) and its
    reader, with the checks `rbp plan` adds."""
    from planning.config_io import ConfigError, config_from_dict, config_to_dict
    from planning.pipeline import PipelineConfig
    from rb_drake.errors import RbpInputError

    def read(doc: Any) -> Any:
        return config_from_dict(PipelineConfig, doc, "fuzz.yaml")

    return config_to_dict(PipelineConfig()), read, (ConfigError, RbpInputError)


def plan_reader() -> tuple[Any, Callable[[Any], Any], tuple[type[BaseException], ...]]:
    """A bundled golden plan and the plan reader's checks on a parsed document (the schema, then
    the typed model and the scenario it holds, as `rbp check` reads it)."""
    import json
    from pathlib import Path

    from planning.plan_file import PlanFileError, parse_plan_text, validated
    from planning.plan_model import Plan, plan_scenario
    from rb_drake.errors import RbpInputError

    golden = Path(__file__).resolve().parents[1] / "tests" / "data" / "golden" / "rig.json"
    base = json.loads(golden.read_text())

    def read(doc: Any) -> Any:
        plan = Plan.from_dict(validated(parse_plan_text(json.dumps(doc, allow_nan=True))))
        plan_scenario(plan, "fuzz.json")
        return plan

    return base, read, (PlanFileError, RbpInputError)


READERS = {"scenario": scenario_reader, "config": config_reader, "plan": plan_reader}


def main(argv: list[str] | None = None) -> int:
    import json
    import sys
    import time

    parser = OneLineParser(prog="python -m experiments.fuzz_readers",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--documents", type=whole(1, 10_000_000), default=10_000, help="per reader")
    parser.add_argument("--seed", type=seed_number, default=0)
    parser.add_argument("--readers", default=",".join(READERS))
    args = parser.parse_args(argv)
    report = {}
    for name in args.readers.split(","):
        base, read, errors = READERS[name]()
        rng = np.random.default_rng(args.seed)
        t0 = time.perf_counter()
        failures, slowest = [], 0.0
        for k in range(args.documents):
            doc = mutate(base, rng, edits=int(rng.integers(1, 6)))
            t1 = time.perf_counter()
            failures += [(k, why) for _, why in run_reader(read, [doc], errors)]
            slowest = max(slowest, time.perf_counter() - t1)
        report[name] = {"documents": args.documents, "failures": len(failures),
                        "first_failures": failures[:5], "seconds": time.perf_counter() - t0,
                        "slowest_document_s": slowest}
        print(f"{name}: {args.documents} documents, {len(failures)} failures, slowest "
              f"{slowest:.3f} s", file=sys.stderr)
    print(json.dumps(report, indent=1))
    return 1 if any(r["failures"] for r in report.values()) else 0


if __name__ == "__main__":
    raise SystemExit(main())
