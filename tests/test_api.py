"""The Python API (`import rbp`, rbp/api.py) end to end: a bundled cave planned footsteps-only
and fully, checked, written and read back, simulated and drawn; a generated cave repeated by
its seed; and `import rbp` staying free of Drake and numba."""

from __future__ import annotations

import ast
import inspect
import socket
import subprocess
import sys
import time
import typing
from pathlib import Path
from urllib.parse import urlparse

import pytest

import rbp
import rbp.api

ROOT = Path(__file__).resolve().parents[1]


def test_import_rbp_loads_neither_drake_nor_numba() -> None:
    code = ("import rbp, sys; rbp.__all__; "
            "print('pydrake' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.split()
    assert out == ["False", "False"]


def _type_checking_names() -> dict[str, object]:
    """The names rbp/api.py imports only for type checkers (its `if TYPE_CHECKING:` block),
    imported for real, so that every string annotation can be resolved."""
    source = Path(rbp.api.__file__).read_text()
    namespace: dict[str, object] = {}
    for node in ast.parse(source).body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING":
            exec(compile(ast.Module(node.body, []), rbp.api.__file__, "exec"), namespace)
    assert namespace, "rbp/api.py has no TYPE_CHECKING block to resolve its annotations"
    return namespace


def _public_functions() -> list[tuple[str, object]]:
    """rbp.api's public functions, and the public methods and properties of its classes."""
    found = []
    for name in rbp.api.__all__:
        value = getattr(rbp.api, name)
        if inspect.isfunction(value):
            found.append((name, value))
        elif inspect.isclass(value):
            for attr, member in vars(value).items():
                if attr.startswith("_"):
                    continue
                if isinstance(member, property):
                    member = member.fget
                if inspect.isfunction(member):
                    found.append((f"{name}.{attr}", member))
    return found


def test_the_surface_is_typed_and_documented() -> None:
    """Every public name has a docstring; every public function and method annotates each
    parameter and its return, and every annotation resolves to a real type."""
    assert sorted(rbp.__all__) == sorted(rbp._LAZY)
    for name in rbp.__all__:
        value = getattr(rbp, name)
        assert inspect.getdoc(value), f"rbp.{name} has no docstring"
    namespace = {**vars(rbp.api), **_type_checking_names()}
    functions = _public_functions()
    assert {"plan", "simulate", "meshcat", "MeshcatView.close"} <= {n for n, _ in functions}
    for name, fn in functions:
        assert inspect.getdoc(fn), f"{name} has no docstring"
        params = [p for p in inspect.signature(fn).parameters if p != "self"]
        hints = typing.get_type_hints(fn, globalns=namespace)
        missing = [p for p in [*params, "return"] if p not in hints]
        assert not missing, f"{name}: no type hint for {missing}"
    with pytest.raises(AttributeError):
        rbp.no_such_name  # noqa: B018


@pytest.fixture(scope="module")
def demo() -> rbp.Scenario:
    return rbp.load_scenario("demo-shaft")


@pytest.fixture(scope="module")
def full_plan(demo: rbp.Scenario) -> rbp.Plan:
    return rbp.plan(demo)


@pytest.fixture(scope="module")
def simulated(full_plan: rbp.Plan) -> rbp.SimulationResult:
    """The full plan's deterministic climb and 50 Monte Carlo trials (simulated once)."""
    return rbp.simulate(full_plan, trials=50, seed=1)


def test_load_a_bundled_cave(demo: rbp.Scenario) -> None:
    assert "demo-shaft" in rbp.bundled_caves()
    assert demo.name and len(demo.anchors) >= 4
    same = rbp.load_scenario(rbp.bundled_caves()["demo-shaft"])
    assert same.to_dict() == demo.to_dict()
    with pytest.raises(rbp.RbpInputError):
        rbp.load_scenario("no-such-cave")


def test_plan_footsteps_only(demo: rbp.Scenario) -> None:
    plan = rbp.plan(demo, footsteps_only=True)
    assert isinstance(plan, rbp.Plan)
    assert plan.success, plan.reason
    assert plan.regrasps > 0 and plan.time_step is None
    assert rbp.check(plan) == []


def test_plan_check_write_read_simulate_draw(full_plan: rbp.Plan, demo: rbp.Scenario,
                                            simulated: rbp.SimulationResult,
                                            tmp_path: Path) -> None:
    assert full_plan.success, full_plan.reason
    assert full_plan.time_step is not None  # a full plan: trajectories
    assert rbp.check(full_plan) == []
    assert rbp.check(full_plan, demo) == []
    other = rbp.load_scenario("shaft-1")
    assert any(p.startswith("scenario:") for p in rbp.check(full_plan, other))

    path = rbp.write_plan(full_plan, tmp_path / "climb.json")
    assert rbp.read_plan(path) == full_plan

    picture = rbp.draw(full_plan, tmp_path / "climb.png")
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cave = rbp.draw(demo, tmp_path / "cave.png")
    assert cave.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    result = simulated
    assert result.success
    assert result.tracking["max_position_error"] < 0.05
    assert 0 < result.p_sim <= 1 and result.p_path == full_plan.p_path
    mc = result.monte_carlo
    assert mc is not None and mc.trials == 50 and 0 <= mc.successes <= 50
    assert result.to_json()["trials"] == 50


def test_generate_a_cave_by_seed() -> None:
    a = rbp.generate_scenario("shaft", seed=3)
    b = rbp.generate_scenario("shaft", seed=3)
    c = rbp.generate_scenario("shaft", seed=4)
    assert a.to_dict() == b.to_dict()
    assert a.to_dict() != c.to_dict()
    assert a.name == "shaft-3"
    with pytest.raises(rbp.RbpInputError):
        rbp.generate_scenario("tunnel", seed=3)
    with pytest.raises(rbp.RbpInputError):
        rbp.generate_scenario("shaft", seed=3, length=(5.0, 4.0))


def test_a_failed_plan_is_not_simulated(demo: rbp.Scenario) -> None:
    cfg = rbp.PipelineConfig(footstep=rbp.FootstepConfig(max_expansions=1,
                                                         expansions_per_metre=0.0))
    plan = rbp.plan(demo, cfg, footsteps_only=True)
    assert not plan.success
    with pytest.raises(rbp.RbpInputError):
        rbp.simulate(plan)
    with pytest.raises(rbp.RbpInputError):
        rbp.meshcat(plan)  # replayed only once simulated


def test_simulate_with_replanning(full_plan: rbp.Plan) -> None:
    """`replan="retry"` (as `rbp simulate --replan retry`) continues failed trials; a few
    trials keep it short (each failed one is simulated again)."""
    with pytest.raises(rbp.RbpInputError):
        rbp.simulate(full_plan, replan="retry")  # no trials to continue
    mc = rbp.simulate(full_plan, trials=12, seed=1, replan="retry").monte_carlo
    assert mc is not None and mc.replanning is not None
    assert mc.replanning.strategy == "retry"
    assert mc.replanning.successes >= mc.successes


def _listening(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(1.0)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def _assert_serves_then_closes(view: rbp.MeshcatView) -> None:
    """A view's URL is on the loopback interface, its server answers there, and `close()`
    stops it (the port refuses connections afterwards)."""
    url = urlparse(view.url)
    assert url.scheme == "http" and url.hostname in ("localhost", "127.0.0.1"), view.url
    assert url.port is not None and _listening(url.port), f"nothing answers at {view.url}"
    view.close()
    assert view.server is None
    for _ in range(20):  # the server thread stops within moments
        if not _listening(url.port):
            break
        time.sleep(0.05)
    assert not _listening(url.port), f"{view.url} still answers after close()"


def test_meshcat_shows_a_cave_and_a_climb(demo: rbp.Scenario,
                                         simulated: rbp.SimulationResult,
                                         tmp_path: Path) -> None:
    """`rbp.meshcat` serves a cave alone and a simulated climb's replay on 127.0.0.1, saves
    the replay as a page and stops when closed; a SimulationResult is replayed as it is."""
    with pytest.raises(rbp.RbpInputError):
        rbp.meshcat(demo, speedup=0.0)
    cave = rbp.meshcat(demo)
    assert cave.frames == 0
    assert cave.server.HasPath("/drake/rbp/cave/rock0")
    _assert_serves_then_closes(cave)
    with pytest.raises(RuntimeError):
        cave.save_html(tmp_path / "closed.html")

    result = simulated
    duration = float(result.record.times[-1])
    with rbp.meshcat(result, speedup=4.0) as climb:
        # one frame per 1/20 s of replay, the climb 4 times faster (a frame either way)
        assert abs(climb.frames - duration / 4.0 * 20.0) <= 2, (climb.frames, duration)
        page = climb.save_html(tmp_path / "climb.html")
        assert "set_animation" in page.read_text(), "the page must carry the replay"
        url = urlparse(climb.url)
    assert climb.server is None, "leaving the with block must close the view"
    assert url.port is not None and not _listening(url.port)
