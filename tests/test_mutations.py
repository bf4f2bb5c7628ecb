"""Mutation testing of the verifier: random single faults (planning.plan_faults) in the plans
of three bundled caves, each of which `rbp check` must reject with one of its fault class's
rules, naming the phase the fault is in (or a neighbour). Hypothesis draws the cave, the fault
class and the fault's random stream; a failure shrinks to the simplest stream."""

from __future__ import annotations

import numpy as np
from conftest import MUTATION_CAVES
from hypothesis import given, settings
from hypothesis import strategies as st

from planning.plan_faults import FAULTS, judge, random_fault


@settings(max_examples=120, deadline=None, derandomize=True)
@given(cave=st.sampled_from(MUTATION_CAVES), kind=st.sampled_from(sorted(FAULTS)),
       seed=st.integers(0, 2**32 - 1))
def test_every_single_fault_is_rejected_with_its_rule(cave_plans, cave: str, kind: str,
                                                      seed: int) -> None:
    plan = cave_plans[cave]
    fault = random_fault(plan, np.random.default_rng(seed), kind)
    verdict = judge(fault)
    assert verdict.rejected, f"{cave}: {fault.what}: accepted"
    assert verdict.right_rule, (
        f"{cave}: {fault.what}: rejected by {sorted(verdict.rules)}, expected one of "
        f"{sorted(fault.rules)}")
    assert verdict.located, f"{cave}: {fault.what}: no {sorted(fault.rules)} problem in phase " \
                            f"{fault.phase} or a neighbour"


def test_faults_leave_the_plan_untouched(cave_plans) -> None:
    import json

    plan = cave_plans[MUTATION_CAVES[0]]
    before = json.dumps(plan, sort_keys=True)
    rng = np.random.default_rng(7)
    for kind in FAULTS:
        random_fault(plan, rng, kind)
    assert json.dumps(plan, sort_keys=True) == before, "a fault changed the original plan"


def test_every_fault_class_is_documented() -> None:
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "formats.md").read_text()
    for kind in FAULTS:
        assert f"| `{kind}` |" in text, f"fault class {kind} not in docs/formats.md"


def test_the_benchmark_script_runs_and_counts(tmp_path, capsys) -> None:
    import json

    from experiments.mutation_bench import main

    out = tmp_path / "bench.json"
    assert main(["--faults", "30", "--caves", "demo-shaft", "--seed", "5", "--out",
                 str(out)]) == 0, capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data["accepted"] == [] and data["misattributed"] == [], data
    assert sum(data["by_class"].values()) == 30, data["by_class"]
    assert "0 accepted" in capsys.readouterr().out
