"""The results of `rbp bench`: the machine they were measured on, the JSON encoding, and
--compare's new/old ratio of every summary metric."""

from __future__ import annotations

import dataclasses
import os
import platform
from pathlib import Path
from typing import Any

import numpy as np

from experiments.bench.stats import fmt, ratio
from rb_drake.errors import one_line


def flat_metrics(result: dict[str, Any]) -> dict[str, float]:
    """Every numeric summary value as section.path.to.value -> number (booleans left out)."""
    out: dict[str, float] = {}

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for key, v in value.items():
                walk(f"{prefix}.{key}", v)
        elif isinstance(value, int | float) and not isinstance(value, bool):
            out[prefix] = float(value)

    for name, section in result.get("sections", {}).items():
        walk(name, section.get("summary", {}))
    return out


def compare(old: dict[str, Any], new: dict[str, Any]) -> list[tuple[str, float, float,
                                                                  float | None]]:
    """(metric, old, new, new/old) for every summary metric in both results."""
    a, b = flat_metrics(old), flat_metrics(new)
    return [(key, a[key], b[key], ratio(b[key], a[key])) for key in b if key in a]


def print_comparison(old: dict[str, Any], new: dict[str, Any], label: str) -> None:
    rows = compare(old, new)
    # the file's name and its `created` escaped: a control character or a lone surrogate
    # (UnicodeEncodeError on a UTF-8 stdout) there was printed raw or crashed after the run
    created = one_line(str(old.get("created", "?")))
    print(f"\ncompared with {one_line(label)} ({created}): new/old per metric")
    width = max((len(k) for k, *_ in rows), default=10)
    for key, a, b, new_over_old in rows:
        # Four significant digits: a fixed number of decimals loses a ratio far below 1.
        print(f"  {key:{width}s} {a:11.4g} -> {b:11.4g}  {fmt(new_over_old, '10.4g')}")
    if not rows:
        print("  no metric in common")


def machine() -> dict[str, Any]:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model or platform.processor(), "cores": os.cpu_count(),
            "machine": platform.machine(),
            "python": f"{platform.python_implementation()} {platform.python_version()}"}


def jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):  # an instance
        return dataclasses.asdict(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
