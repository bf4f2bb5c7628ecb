"""What the benchmark's sections share: medians and quantiles of finite values, ratios, and
the formatting of numbers that may be missing."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def quantiles(values: Iterable[float]) -> dict[str, float | None]:
    """Median, 90th percentile and maximum of the finite values (None when there are none)."""
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if not len(v):
        return {"median": None, "p90": None, "max": None}
    return {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
            "max": float(v.max())}


def median(values: Iterable[float]) -> float | None:
    return quantiles(values)["median"]


def ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else a / b


def count(items: Iterable[str]) -> str:
    out: dict[str, int] = {}
    for item in items:
        out[item] = out.get(item, 0) + 1
    return ", ".join(f"{n} {k}" for k, n in out.items())


def fmt(x: float | None, spec: str = ".2g") -> str:
    return "-" if x is None else format(x, spec)
