"""OMPL benchmark logs of the footstep experiments, for Planner Arena and OMPL's tools.

Motion-planning results are compared in OMPL's benchmark log format (MoveIt writes it too):
`ompl_benchmark_statistics LOG -d DB.sqlite` (installed with the ompl package) turns a log into
the SQLite database Planner Arena (plannerarena.org) plots. `baseline_comparison` and
`route_quality` write one with `--ompl-log PATH`: one experiment, a planner per footstep planner
or search variant, a run per cave, in the grammar of OMPL's `Benchmark::saveResultsToStream`
(ompl/tools/benchmark/src/Benchmark.cpp) as its parser reads it.

The text is built by pure functions of the experiments' records (`baseline_log`,
`route_quality_log`, then `log_text`); `write_log` writes it atomically. The properties and
the meaning of the `stop` values are in docs/formats.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

Value = bool | int | float | str | None

# How the footstep search stopped (`planning.search_outcome.Stop`, "" a route), as the values
# of the `stop` enum: a run holds the index. The enum is named `stop`, not OMPL's `status`: in a
# database that also holds OMPL's logs, the parser keeps the first `status` enum it meets, and
# rbp's values would be read with OMPL's names.
STOPS = (("", "route found"),
         ("budget", "budget stop (expansions or time limit)"),
         ("exhausted", "search exhausted (no proof)"),
         ("noroute", "no route proved"),
         ("nostart", "start joins no lattice pose"),
         ("nocave", "no cave (the generator gave no start stance)"))
CAVE_KINDS = ("shaft", "crevasse", "rockfall")
ENUMS = {"stop": tuple(text for _, text in STOPS), "cave_kind": CAVE_KINDS}

# The run properties, "name TYPE" as the log declares them (OMPL sorts them; so do we).
RUN_PROPERTIES = ("bound REAL", "cave_kind ENUM", "cave_seed INTEGER", "cost REAL",
                  "expansions INTEGER", "memory REAL", "p_grasps REAL", "p_path REAL",
                  "peak_memory REAL", "regrasps INTEGER", "solved BOOLEAN", "stop ENUM",
                  "time REAL", "verified BOOLEAN")
# An anytime search's improvements (the plan's search history), OMPL's progress properties.
PROGRESS_PROPERTIES = ("best cost REAL", "bound REAL", "expansions INTEGER", "lower bound REAL",
                       "time REAL")


@dataclasses.dataclass(frozen=True)
class Run:
    """One planner on one cave: run property ("name TYPE") -> value (None: not measured), and
    the anytime search's progress samples (progress property -> value), oldest first."""

    values: Mapping[str, Value]
    progress: tuple[Mapping[str, Value], ...] = ()


@dataclasses.dataclass(frozen=True)
class PlannerLog:
    name: str
    common: Mapping[str, Value]  # its configuration: "name = value" lines
    runs: tuple[Run, ...]


@dataclasses.dataclass(frozen=True)
class BenchmarkLog:
    """What an OMPL benchmark log holds: the experiment's header, then each planner's runs."""

    experiment: str
    version: str                         # "rbp version X": the parser's library and version
    host: str
    started: datetime
    setup: str                           # free text: how the experiment was run
    cpu: str                             # free text: the machine
    seed: int
    time_limit: float                    # s per run, 0: none
    memory_limit: float                  # MB per run, 0: none
    total_seconds: float
    planners: tuple[PlannerLog, ...]
    properties: Mapping[str, Value] = dataclasses.field(default_factory=dict)  # "name TYPE"
    enums: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=lambda: ENUMS)


def _text(value: Value) -> str:
    """A value as the log writes it: booleans 1 / 0 (as OMPL), a missing or non-finite number
    empty (the parser stores NULL)."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    return str(value)


def _word(text: str, what: str) -> str:
    """`text` as one word: the parser takes the header's last token (experiment, host)."""
    word = "_".join(str(text).split())
    if not word:
        raise ValueError(f"{what}: empty")
    return word


def _line(text: str, what: str, forbidden: Sequence[str] = ()) -> str:
    if "\n" in text or "\r" in text or any(f in text for f in forbidden):
        raise ValueError(f"{what}: {text!r} cannot be written on one log line")
    return text


def _block(text: str) -> str:
    """A multi-line value between <<<| and |>>>."""
    body = text if text.endswith("\n") or not text else text + "\n"
    if any(line.startswith("|>>>") for line in body.splitlines()):
        raise ValueError("a multi-line value cannot hold a line starting |>>>")
    return f"<<<|\n{body}|>>>\n"


def _declared(name: str, what: str) -> tuple[str, str]:
    """A declared property "name TYPE": its name and type (both one word or more, no '=')."""
    parts = _line(name, what, ("=", ";", ",")).split()
    if len(parts) < 2:
        raise ValueError(f"{what}: {name!r} needs a name and a type")
    return " ".join(parts[:-1]), parts[-1]


def log_text(log: BenchmarkLog) -> str:
    """The log, in the grammar of OMPL's `Benchmark::saveResultsToStream`.

    Raises ValueError when a name or value cannot be written so that the parser reads it back
    (a newline in it, a run value holding "; ", an enum value holding "|")."""
    out = [f"{_line(log.version, 'version')}\n",
           f"Experiment {_word(log.experiment, 'experiment name')}\n",
           f"{len(log.properties)} experiment properties\n"]
    for name, value in log.properties.items():
        _declared(name, "experiment property")
        out.append(f"{name} = {_line(_text(value), name, (' = ',))}\n")
    out += [f"Running on {_word(log.host, 'host')}\n",
            f"Starting at {log.started.strftime('%Y-%m-%d %H:%M:%S')}\n",
            _block(log.setup), _block(log.cpu),
            f"{int(log.seed)} is the random seed\n",
            f"{float(log.time_limit)!r} seconds per run\n",
            f"{float(log.memory_limit)!r} MB per run\n",
            f"{max((len(p.runs) for p in log.planners), default=0)} runs per planner\n",
            f"{float(log.total_seconds)!r} seconds spent to collect the data\n",
            f"{len(log.enums)} enum type{'' if len(log.enums) == 1 else 's'}\n"]
    for name, values in log.enums.items():
        out.append("|".join(_line(v, f"enum {name}", ("|",)) for v in (name, *values)) + "\n")
    out.append(f"{len(log.planners)} planners\n")
    for planner in log.planners:
        out += _planner_lines(planner)
    return "".join(out)


def _planner_lines(planner: PlannerLog) -> list[str]:
    out = [_line(planner.name, "planner name") + "\n", f"{len(planner.common)} common properties\n"]
    for key in sorted(planner.common):
        out.append(f"{_line(key, 'common property', ('=',))} = "
                   f"{_line(_text(planner.common[key]), key)}\n")
    names = sorted({k for run in planner.runs for k in run.values})
    for name in names:
        _declared(name, "run property")
    out.append(f"{len(names)} properties for each run\n")
    out += [f"{name}\n" for name in names]
    out.append(f"{len(planner.runs)} runs\n")
    for run in planner.runs:
        out.append("".join(f"{_line(_text(run.values.get(n)), n, ('; ',))}; " for n in names)
                   + "\n")
    if any(run.progress for run in planner.runs):
        progress = sorted({k for run in planner.runs for p in run.progress for k in p})
        for name in progress:
            _declared(name, "progress property")
        out.append(f"{len(progress)} progress properties for each run\n")
        out += [f"{name}\n" for name in progress]
        out.append(f"{len(planner.runs)} runs\n")
        for run in planner.runs:  # a sample: each value and ",", then ";"
            out.append("".join("".join(f"{_line(_text(p.get(n)), n, (',', ';'))},"
                                       for n in progress) + ";" for p in run.progress) + "\n")
    out.append(".\n")
    return out


def write_log(path: str | Path, log: BenchmarkLog) -> Path:
    """Write the log at `path` atomically; returns the path."""
    from rb_drake.files import atomic_write_text

    return atomic_write_text(path, log_text(log))


def stop_index(record: Mapping[str, Any]) -> int | None:
    """The `stop` enum's value of a planner's record (None: not known)."""
    stop = record.get("stop")
    if stop is None and str(record.get("reason", "")).startswith("no cave"):
        stop = "nocave"
    codes = [code for code, _ in STOPS]
    return codes.index(stop) if stop in codes else None


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else None


def progress_of(history: Sequence[Mapping[str, Any]] | None) -> tuple[dict[str, Value], ...]:
    """An anytime search's history (the plan's search record) as progress samples: when, the
    best cost then, the proven lower bound, their ratio (bound: the cost is at most this times
    the optimum's) and the expansions so far. A repeated time is left out (the parser keys
    samples by run and time)."""
    samples: list[dict[str, Value]] = []
    seen: set[float] = set()
    for point in history or ():
        t = float(point["seconds"])
        if t in seen:
            continue
        seen.add(t)
        cost, low = float(point["cost"]), float(point["lower_bound"])
        samples.append({"time REAL": t, "best cost REAL": cost, "lower bound REAL": low,
                        "bound REAL": cost / low if low > 0 else None,
                        "expansions INTEGER": int(point["expansions"])})
    return tuple(samples)


def run_of(record: Mapping[str, Any], seconds: float | None, kind: str, seed: int,
           measures: Mapping[str, Any] | None = None) -> Run:
    """A planner's record of one cave (an experiment's: success, stop, regrasps, p_path, ...)
    as a run. `measures`: what varies from run to run (peak_memory_mb, kept_memory_mb, history),
    kept apart from the record by the sweeps. The route's numbers (regrasps, p_path, cost, ...)
    are written only for a plan found: a failed plan has none."""
    measures = measures or {}
    solved = bool(record.get("success"))
    route = {k: record.get(k) if solved else None
             for k in ("regrasps", "p_path", "p_grasps", "cost", "bound")}
    values: dict[str, Value] = {
        "time REAL": _number(seconds), "solved BOOLEAN": solved,
        "stop ENUM": stop_index(record),
        "regrasps INTEGER": None if route["regrasps"] is None else int(route["regrasps"]),
        "p_path REAL": _number(route["p_path"]), "p_grasps REAL": _number(route["p_grasps"]),
        "cost REAL": _number(route["cost"]), "bound REAL": _number(route["bound"]),
        "expansions INTEGER": (int(record["expansions"])
                               if isinstance(record.get("expansions"), int) else None),
        "memory REAL": _number(measures.get("kept_memory_mb")),
        "peak_memory REAL": _number(measures.get("peak_memory_mb")),
        "cave_kind ENUM": CAVE_KINDS.index(kind) if kind in CAVE_KINDS else None,
        "cave_seed INTEGER": int(seed)}
    if "verified" in record:
        values["verified BOOLEAN"] = bool(record["verified"])
    return Run(values, progress_of(measures.get("history")))


def flat(config: Mapping[str, Any], prefix: str = "") -> dict[str, Value]:
    """A nested configuration as dotted keys (lists as compact JSON): common properties."""
    out: dict[str, Value] = {}
    for key, value in config.items():
        if isinstance(value, Mapping):
            out.update(flat(value, f"{prefix}{key}."))
        elif isinstance(value, list | tuple):
            out[f"{prefix}{key}"] = json.dumps(value, separators=(",", ":"))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _machine(machine: Mapping[str, Any]) -> tuple[str, str]:
    cpu = "\n".join(f"{k}: {v}" for k, v in machine.items() if k != "host")
    return str(machine.get("host", "UNKNOWN")), cpu


def baseline_log(records: Sequence[Mapping[str, Any]], planners: Sequence[str],
                 params: Mapping[str, Any], common: Mapping[str, Mapping[str, Any]],
                 machine: Mapping[str, Any], started: datetime,
                 time_limit: float = 0.0, memory_limit: float = 0.0) -> BenchmarkLog:
    """The log of a `baseline_comparison` run: its trials' records (those that ran without
    error), a planner per name in `planners` with its configuration `common[planner]`, and
    the run's parameters (results.json's `params`). A run's time is the planner's whole
    planning time (`timing.total`: its footsteps, and with --motion the rest)."""
    logs = []
    for p in planners:
        runs = []
        for r in records:
            timing = r["timing"].get(p, {})
            runs.append(run_of(r["result"][p], timing.get("total", timing.get("footstep")),
                               r["params"]["kind"], r["params"]["seed"], timing.get("search")))
        logs.append(PlannerLog(p, flat(common.get(p, {})), tuple(runs)))
    host, cpu = _machine(machine)
    properties: dict[str, Value] = {
        "trials INTEGER": int(params["trials"]), "first_seed INTEGER": int(params["first_seed"]),
        "cave_kinds TEXT": str(params["kind"]),
        "length_min REAL": float(params["length"][0]),
        "length_max REAL": float(params["length"][1]),
        "max_expansions INTEGER": int(params["max_expansions"]),
        "motion BOOLEAN": bool(params["motion"])}
    return BenchmarkLog(
        experiment="baseline_comparison", version=f"rbp version {_version()}", host=host,
        started=started, setup=json.dumps(dict(params), indent=1), cpu=cpu,
        seed=int(params["first_seed"]), time_limit=time_limit, memory_limit=memory_limit,
        total_seconds=sum(float(r["timing"].get("trial", 0.0)) for r in records),
        planners=tuple(logs), properties=properties)


def route_quality_log(caves: Sequence[Mapping[str, Any]], variants: Sequence[str],
                      args: Mapping[str, Any], common: Mapping[str, Mapping[str, Any]],
                      machine: Mapping[str, Any], started: datetime, total_seconds: float,
                      time_limit: float = 0.0, memory_limit: float = 0.0) -> BenchmarkLog:
    """The log of a `route_quality` run: a planner per search variant, a run per cave (its
    records hold the footstep search's seconds, memory and history with the route's numbers)."""
    logs = [PlannerLog(v, flat(common.get(v, {})),
                       tuple(run_of(c[v], c[v].get("seconds"), c["kind"], c["seed"], c[v])
                             for c in caves))
            for v in variants]
    host, cpu = _machine(machine)
    length = args.get("length") or (0.0, 0.0)
    properties: dict[str, Value] = {
        "trials INTEGER": len(caves), "first_seed INTEGER": int(args.get("first_seed", 1)),
        "cave_kinds TEXT": str(args.get("kind", "")),
        "length_min REAL": float(length[0]), "length_max REAL": float(length[1])}
    return BenchmarkLog(
        experiment="route_quality", version=f"rbp version {_version()}", host=host,
        started=started, setup=json.dumps(dict(args), indent=1, default=str), cpu=cpu,
        seed=int(args.get("first_seed", 1)), time_limit=time_limit, memory_limit=memory_limit,
        total_seconds=total_seconds, planners=tuple(logs), properties=properties)


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("rbp")
    except metadata.PackageNotFoundError:  # a source tree that is not installed
        return "0.0.0"
