"""Issue 28, probe 8: integers written as floats, closed standard streams, numba's variables,
non-ASCII names on an ASCII stdout, outputs that cannot be written, the Python API's callbacks,
early range checks and argparse's usage errors (each refused in one line, exit 2)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

import rbp
from planning.plan_file import PlanFileError
from tests.cli_helpers import run_rbp


@pytest.fixture(scope="module")
def plan_dict() -> dict[str, Any]:
    """A footstep plan of demo-shaft as a plan-file object (seconds to plan)."""
    plan = rbp.plan("demo-shaft", footsteps_only=True)
    assert plan.success
    return plan.to_dict()


def _reach(plan: dict[str, Any]) -> int:
    return next(k for k, p in enumerate(plan["phases"]) if p["kind"] == "reach")


@pytest.mark.parametrize("where", ["free_boom", "regrasps", "expansions"])
def test_integers_written_as_floats_are_refused_by_every_reader(
        plan_dict: dict[str, Any], where: str, tmp_path: Path) -> None:
    plan = copy.deepcopy(plan_dict)
    k = _reach(plan)
    if where == "free_boom":
        plan["phases"][k]["free_boom"] = float(plan["phases"][k]["free_boom"])
        field = f"phases/{k}/free_boom"
    elif where == "regrasps":
        plan["regrasps"], field = float(plan["regrasps"]), "regrasps"
    else:
        plan["search"]["expansions"] = float(plan["search"]["expansions"])
        field = "search/expansions"
    with pytest.raises(PlanFileError, match=f"^{field}: expected an integer, got "):
        rbp.check(plan)
    path = tmp_path / "p.json"
    path.write_text(json.dumps(plan))
    with pytest.raises(PlanFileError, match="expected an integer"):
        rbp.read_plan(path)
    if where == "free_boom":  # the commands: one line, exit 2 (a traceback before)
        for args in (["check", "p.json"], ["simulate", "p.json", "--trials", "1"]):
            done = run_rbp(*args, cwd=tmp_path)
            assert done.returncode == 2, done.stderr
            assert done.stderr.endswith(f"error: p.json: {field}: expected an integer, "
                                        f"got {plan['phases'][k]['free_boom']}\n"), done.stderr
            assert done.stderr.count("\n") == 1, done.stderr
