"""The trial runner of the experiments: many independent trials, a process pool or a Dask
cluster, one JSON file per finished trial, and resume.

A trial is a pure function of its parameters: `Trial(name, function, params)` names a function
by its import path ("module:function") and the JSON-able keyword arguments to call it with; the
function returns a JSON-able dictionary. Only a key `timing` in it may differ from run to run
(wall-clock measurements): the runner moves it out of the record's `result`, so that a local
and a Dask run give equal results trial by trial.

`run_sweep` writes each record to OUT/trials/NAME.json (atomically) as soon as its trial
finishes, in whatever order trials finish, and skips every trial whose record is already there
with the same function and parameters: an interrupted sweep loses only the trials that were
running. A trial that raises is recorded with its error and run again by the next sweep.
Trials run on a local process pool (`workers`; 1 runs them in this process) or, given
`cluster="tcp://HOST:PORT"`, on a Dask distributed scheduler, which sends the same function to
its workers.
"""

from __future__ import annotations

import argparse
import importlib
import json
import multiprocessing
import os
import platform
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any, NamedTuple

from experiments.arguments import MAX_TRIALS, MAX_WORKERS, json_type, path_name, tcp_address, whole
from experiments.records import shown
from rb_drake.errors import EXIT_INTERRUPTED, EXIT_USAGE, RbpError, one_line
from rb_drake.files import atomic_write_text, output_problem
from rb_drake.input_files import InputFileError, load_json, read_text

RECORD_FORMAT = "rbp-trial/1"


class Trial(NamedTuple):
    """One unit of work: `function(**params)`, recorded as OUT/trials/`name`.json."""

    name: str                # unique within a sweep; a file name (letters, digits, -_.=)
    function: str            # "package.module:function", importable where the trial runs
    params: dict[str, Any]   # JSON-able keyword arguments


class SweepError(RbpError):
    """A sweep that cannot run as asked (bad trial names, a folder holding another sweep)."""


# A trial function's check of a finished record (function path -> check(params, record) ->
# "FIELD: REASON" or None, FIELD dotted from the record: "result.rbp.p_path"), registered by
# the module that makes its trials (rules in experiments.records): a record edited or damaged
# since (p_path "x", 1e308, missing) is refused on resuming, before the summaries read it.
RESULT_CHECKS: dict[str, Callable[[dict[str, Any], dict[str, Any]], str | None]] = {}


def _resolve(path: str) -> Callable[..., dict[str, Any]]:
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


def machine_info() -> dict[str, Any]:
    """The machine a trial ran on: host, cpu model, cores, python and drake versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from importlib.metadata import PackageNotFoundError, version

    try:
        drake = version("drake")
    except PackageNotFoundError:
        drake = "not installed"
    return {"host": socket.gethostname(), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version(), "drake": drake}


def run_trial(trial: Trial) -> dict[str, Any]:
    """Run one trial and return its record (never raises: an exception becomes `error`); the
    worker's part names the machine, the kernel threads and the load when the trial ended
    (`rb_drake.kernel.threads.run_conditions`)."""
    from rb_drake.kernel.threads import run_conditions

    start = time.perf_counter()
    result, error, timing = None, None, {}
    try:
        result = dict(_resolve(trial.function)(**trial.params))
        timing = result.pop("timing", {})
    except Exception as e:  # a bug in one trial must not lose the others
        error = f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=-3)}"
    return {"format": RECORD_FORMAT, "name": trial.name, "function": trial.function,
            "params": trial.params, "result": result, "error": error,
            "timing": timing | {"trial": time.perf_counter() - start},
            "worker": machine_info() | {"pid": os.getpid()} | run_conditions()}


def trial_path(out: str | Path, name: str) -> Path:
    return Path(out) / "trials" / f"{name}.json"


def _check_names(trials: Sequence[Trial]) -> None:
    seen = set()
    for t in trials:
        if not t.name or not all(c.isalnum() or c in "-_.=" for c in t.name):
            raise SweepError(f"trial name {t.name!r}: use letters, digits and -_.= only")
        if t.name in seen:
            raise SweepError(f"trial name {t.name!r}: used twice in one sweep")
        seen.add(t.name)


def finished_record(out: str | Path, trial: Trial) -> dict[str, Any] | None:
    """The trial's stored record if it finished without error, else None.

    Raises SweepError when the folder holds a record of that name for other parameters: the
    folder belongs to another sweep, and mixing the two would be silently wrong."""
    path = trial_path(out, trial.name)
    # before any trial runs: a folder there (or --out a file) failed after the trial's work,
    # and a symlink to a device was replaced by the record
    # a finished record is kept as it is: one made read-only is no reason to refuse the sweep
    if (problem := output_problem(path, may_keep=True)) is not None:
        raise SweepError(f"{path}: --out: {problem}")
    if not path.exists():
        return None
    try:  # within the input bounds: a sweep folder may hold anything (rb_drake.input_files)
        record = load_json(read_text(path), parse_constant=_no_constant)
    except (InputFileError, json.JSONDecodeError, RecursionError):
        return None  # not ours or damaged: run the trial again, the new record replaces it
    except _NonFiniteError as e:  # records are written without them: a summary would write it on
        raise SweepError(f"{path}: (file): holds {e}, which no record does (they are written "
                         "without NaN or Infinity); delete the file to run the trial again"
                         ) from None
    if not isinstance(record, dict):
        return None
    # Compare through JSON, as stored: tuples become lists.
    wanted = json.loads(json.dumps({"function": trial.function, "params": trial.params}))
    if (problem := _other_trial(record, wanted)) is not None:
        raise SweepError(f"{path}: {problem}: use another --out folder or delete it")
    # `error` is what says whether to run the trial again: only null (finished) or a message
    if "error" not in record:
        problem = "error: missing"
    elif record["error"] is not None and not (isinstance(record["error"], str)
                                              and record["error"]):
        problem = f"error: must be null or a non-empty string, got {shown(record['error'])}"
    elif record["error"] is not None:
        return None
    else:
        problem = _record_problem(record, trial)
    if problem is not None:
        raise SweepError(f"{path}: {problem}; delete the file to run the trial again")
    return record


class _NonFiniteError(Exception):
    pass


def _no_constant(name: str) -> Any:
    raise _NonFiniteError(name)


def _other_trial(record: dict[str, Any], wanted: dict[str, Any]) -> str | None:
    """"FIELD: REASON" when the record was made by another trial function or for other
    parameters (naming the first that differs, shortened), or None."""
    if record.get("function") != wanted["function"]:
        return (f"function: made by another trial function ({shown(record.get('function'))}),"
                f" not {wanted['function']!r}")
    params = record.get("params")
    if not isinstance(params, dict):
        return f"params: expected an object, got {json_type(params)}"
    for key in sorted(set(params) | set(wanted["params"]), key=str):
        field = f"params.{key if str(key).isidentifier() else shown(key)}"
        if key not in params:
            return f"{field}: missing: recorded for other parameters"
        if key not in wanted["params"]:
            return f"{field}: recorded for other parameters, not this sweep's"
        if params[key] != wanted["params"][key]:
            return (f"{field}: recorded for other parameters "
                    f"({shown(params[key])}, not {shown(wanted['params'][key])})")
    return None


def _record_problem(record: dict[str, Any], trial: Trial) -> str | None:
    """What is wrong with a finished record's fields ("FIELD: REASON"), or None."""
    if record.get("name") != trial.name:  # the progress line and every summary name it
        return ("name: missing" if "name" not in record
                else f"name: expected {trial.name!r}, got {shown(record['name'])}")
    if record.get("format") != RECORD_FORMAT:
        return f"format: expected {RECORD_FORMAT!r}, got {str(record.get('format'))[:40]!r}"
    for field in ("result", "timing", "worker"):
        if not isinstance(record.get(field), dict):
            return f"{field}: expected an object, got {json_type(record.get(field))}"
    trial_seconds = record["timing"].get("trial", 0.0)
    if not (isinstance(trial_seconds, int | float) and not isinstance(trial_seconds, bool)
            and 0 <= trial_seconds <= 1e9):  # the progress line and the OMPL log add it up
        return f"timing.trial: must be a number of seconds from 0 to 1e9, got " \
               f"{str(trial_seconds)[:40]!r}"
    check = RESULT_CHECKS.get(trial.function)
    return check(trial.params, record) if check is not None else None


class ProgressDisplay:
    """Progress of a sweep on `stream`: a tqdm bar redrawn in place on a terminal, otherwise
    one line per finished trial (logs and CI)."""

    def __init__(self, total: int, skipped: int, stream: IO[str] | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.interactive = self.stream.isatty()
        self.total, self.skipped = total, skipped
        self.done, self.errors = 0, 0
        self.start = time.perf_counter()
        self.bar: Any = None
        if skipped:
            print(f"resuming: {skipped} of {total} trials already finished", file=self.stream,
                  flush=True)
        if self.interactive:
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=skipped, unit=" trials", file=self.stream,
                            dynamic_ncols=True)

    def update(self, record: dict[str, Any]) -> None:
        self.done += 1
        self.errors += record["error"] is not None
        finished = self.skipped + self.done
        if self.bar is not None:
            if self.errors:
                errors = f"{self.errors} error{'' if self.errors == 1 else 's'}"
                self.bar.set_postfix_str(errors, refresh=False)
            self.bar.update(1)
        else:
            status = "ERROR " + record["error"].splitlines()[0] if record["error"] else "done"
            print(f"[{finished}/{self.total}] {record['name']}: {status} "
                  f"({record['timing']['trial']:.1f} s)", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _share_cores(threads: int) -> None:
    """A pool worker's share of the cores for the complete search's compiled kernels
    (`rb_drake.kernel.threads.kernel_threads`, `worker_threads`): workers times threads never
    exceed the cores, whatever RBP_THREADS the sweep was started with."""
    os.environ["RBP_THREADS"] = str(threads)


def _local(trials: list[Trial], workers: int) -> Iterator[dict[str, Any]]:
    if workers == 1:  # in this process: no start-up cost, and a debugger sees the trial
        for t in trials:
            yield run_trial(t)
        return
    # spawn, not fork: the parent may hold pydrake and OMPL state that is unsafe to fork
    from rb_drake.kernel.threads import worker_threads

    pool = multiprocessing.get_context("spawn").Pool(
        workers, initializer=_share_cores, initargs=(worker_threads(workers),))
    try:
        yield from pool.imap_unordered(run_trial, trials, chunksize=1)
        pool.close()
    finally:  # on an interruption, stop the running trials now: their records are lost anyway
        pool.terminate()
        pool.join()


def _dask(trials: list[Trial], address: str) -> Iterator[dict[str, Any]]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise SweepError("--cluster needs Dask: pip install 'dask[distributed]'") from None
    with Client(address, timeout="30s") as client:
        # pure=False: every submission runs, even of a trial the cluster has seen before
        futures = [client.submit(run_trial, t, pure=False) for t in trials]
        try:
            for future in as_completed(futures):
                yield future.result()
        finally:
            client.cancel(futures)


def run_sweep(trials: Iterable[Trial], out: str | Path, workers: int | None = None,
              cluster: str | None = None, stream: IO[str] | None = None) -> list[dict[str, Any]]:
    """Run every trial whose record is not already in OUT/trials/, write each record as its
    trial finishes, and return all the records in the order of `trials`.

    `workers`: local processes (default: one per core; 1 runs in this process). `cluster`: the
    address of a Dask scheduler ("tcp://HOST:PORT") to send the trials to instead."""
    trials = list(trials)
    _check_names(trials)
    if workers is not None and workers < 1:
        raise SweepError(f"--workers: must be 1 or more, got {workers}")
    for folder in (Path(out), Path(out) / "trials"):  # the records go there: a folder or none
        if folder.exists() and not folder.is_dir():
            raise SweepError(f"{folder}: --out: is not a folder; give a folder (the trials' "
                             "records are written into OUT/trials/)")
    records: dict[str, dict[str, Any]] = {}
    for t in trials:
        record = finished_record(out, t)
        if record is not None:
            records[t.name] = record
    pending = [t for t in trials if t.name not in records]
    if not pending:
        print(f"all {len(trials)} trials already finished in {Path(out) / 'trials'}",
              file=stream if stream is not None else sys.stderr, flush=True)
    else:
        progress = ProgressDisplay(len(trials), len(records), stream)
        workers = workers or os.cpu_count() or 1
        runs = _dask(pending, cluster) if cluster else _local(pending, min(workers, len(pending)))
        try:
            for record in runs:
                atomic_write_text(trial_path(out, record["name"]),
                                  json.dumps(record, indent=1, allow_nan=False) + "\n")
                records[record["name"]] = record
                progress.update(record)
        finally:
            progress.close()
    return [records[t.name] for t in trials]


def ok_records(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records of trials that ran without error."""
    return [r for r in records if r["error"] is None]


def add_sweep_arguments(parser: argparse.ArgumentParser, trials: int, out: str) -> None:
    """The flags every sweep shares: --out, --trials, --workers, --cluster."""
    parser.add_argument("--out", type=path_name, default=out, help=f"output folder (default {out})")
    parser.add_argument("--trials", type=whole(1, MAX_TRIALS), default=trials,
                        help=f"number of trials, 1 to {MAX_TRIALS:,} (default {trials})")
    parser.add_argument("--workers", type=whole(1, MAX_WORKERS), default=None,
                        help=f"local worker processes, 1 to {MAX_WORKERS} (default: one per "
                             "core; 1: in this process)")
    parser.add_argument("--cluster", metavar="tcp://HOST:PORT", type=tcp_address,
                        help="run the trials on this Dask distributed scheduler instead")


def check_sweep_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    if args.trials < 1:
        parser.error(f"--trials: must be 1 or more, got {args.trials}")
    if args.workers is not None and args.workers < 1:
        parser.error(f"--workers: must be 1 or more, got {args.workers}")


def sweep(trials: Iterable[Trial], args: argparse.Namespace,
          experiment: str | None = None) -> list[dict[str, Any]]:
    """`run_sweep` with the shared flags, for a script: a sweep that cannot run ends it with
    one line on stderr (status EXIT_USAGE), an interruption with a line on how to resume
    (EXIT_INTERRUPTED, as every rbp command). `experiment`: the script's name, which its
    OUT/results.json records; a folder whose results.json another experiment wrote is refused
    (`--out` of another experiment's folder: its results were replaced after the work)."""
    try:
        if experiment is not None:
            results_owner_check(args.out, experiment)
        return run_sweep(trials, args.out, args.workers, args.cluster)
    except SweepError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    except KeyboardInterrupt:
        print(f"interrupted: finished trials are kept in {Path(args.out) / 'trials'}; run the "
              "same command again to resume", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None


def results_owner_check(out: str | Path, experiment: str) -> None:
    """Raise SweepError when OUT/results.json holds another experiment's results (its
    "experiment" field); a file rbp cannot read as such is replaced as before."""
    path = Path(out) / "results.json"
    try:
        results = load_json(read_text(path))
    except (InputFileError, json.JSONDecodeError, RecursionError, OSError):
        return
    other = results.get("experiment") if isinstance(results, dict) else None
    if isinstance(other, str) and other != experiment:
        raise SweepError(f"{path}: --out: holds the results of the experiment "
                         f"{shown(other)}, which {experiment} would replace; give it another "
                         "--out folder")


def check_out_files(out: str | Path, names: Sequence[str]) -> None:
    """End a script with one line naming --out (status EXIT_USAGE) when the files `names`
    cannot be written in output folder `out`, before the work, as a sweep's trials are
    (`finished_record`): snapshots and rig_experiment found out only after planning, without
    naming the option."""
    for name in names:
        path = Path(out) / name
        if (problem := output_problem(path)) is not None:
            print(one_line(f"error: {path}: --out: {problem}"), file=sys.stderr)
            raise SystemExit(EXIT_USAGE)


def write_results(out: str | Path, results: dict[str, Any], name: str = "results.json") -> Path:
    """OUT/results.json (atomically), with the machine that summarised it."""
    path = atomic_write_text(Path(out) / name,
                             json.dumps(results, indent=1, allow_nan=False) + "\n")
    print(f"wrote {path}")
    return path


def quantiles(values: Sequence[float]) -> dict[str, float | int | None]:
    """Median, quartiles, mean, min and max of `values` (None when empty)."""
    import numpy as np

    if not len(values):
        return {"n": 0, "median": None, "q1": None, "q3": None, "mean": None, "min": None,
                "max": None}
    v = np.asarray(values, dtype=float)
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {"n": len(v), "median": float(med), "q1": float(q1), "q3": float(q3),
            "mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
