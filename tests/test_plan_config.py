"""The planner's configuration as data (planning.config_io), the plan's provenance, `rbp plan
--config FILE` and `rbp plan --from-plan PLAN`."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import pytest
import yaml
from cli_helpers import run_rbp
from conftest import SHAFT

from planning.config_io import ConfigError, config_from_dict, config_to_dict, load_config
from planning.footsteps import FootstepConfig
from planning.pipeline import PipelineConfig
from planning.plan import validate
from planning.scp import ScpConfig


def test_default_config_round_trips_through_json() -> None:
    cfg = PipelineConfig()
    data = json.loads(json.dumps(config_to_dict(cfg), allow_nan=False))
    assert data["scp"]["radius_velocity"] == "inf", data["scp"]["radius_velocity"]
    assert config_from_dict(PipelineConfig, data, "x") == cfg


def test_changed_config_round_trips() -> None:
    cfg = PipelineConfig(footstep=FootstepConfig(seed=7, max_expansions=33), dt=0.25,
                         scp=ScpConfig(solver="osqp", radius_velocity=1.5), optimise=False)
    back = config_from_dict(PipelineConfig, config_to_dict(cfg), "x")
    assert back == cfg, f"{back} != {cfg}"


def test_keys_left_out_keep_the_base() -> None:
    cfg = config_from_dict(PipelineConfig, {"seed": {"ompl_time": 2}}, "x")
    base = PipelineConfig()
    assert cfg.seed.ompl_time == 2.0 and isinstance(cfg.seed.ompl_time, float)
    # PipelineConfig's own seed default (5 cm steps) stays, not SeedConfig's class default
    assert cfg.seed.step == base.seed.step and cfg.footstep == base.footstep


@dataclasses.dataclass(frozen=True)
class Inner:
    gain: float = 1.0
    names: tuple[str, ...] = ("a",)


@dataclasses.dataclass(frozen=True)
class Outer:
    """A configuration the reader was not written for: it follows the fields' types."""

    inner: Inner = dataclasses.field(default_factory=Inner)
    flag: bool = False
    limit: int | None = None
    pair: tuple[float, float] = (0.0, 1.0)


def test_reader_is_generic_over_dataclass_fields() -> None:
    data = {"inner": {"gain": 3, "names": ["x", "y"]}, "flag": True, "limit": None,
            "pair": [2, 3.5]}
    cfg = config_from_dict(Outer, data, "o.yaml")
    assert cfg == Outer(Inner(3.0, ("x", "y")), True, None, (2.0, 3.5)), cfg
    assert config_from_dict(Outer, config_to_dict(cfg), "o.yaml") == cfg
    assert config_from_dict(Outer, {"limit": 4}, "o.yaml").limit == 4


@pytest.mark.parametrize("data, field, words", [
    ({"footstep": {"max_expansion": 5}}, "footstep.max_expansion",
     ("unknown key", "max_expansions")),
    ({"footsteps": {}}, "footsteps", ("unknown key", "footstep")),
    ({"footstep": {"max_expansions": "many"}}, "footstep.max_expansions",
     ("integer", "many")),
    ({"footstep": {"max_expansions": 2.5}}, "footstep.max_expansions", ("integer",)),
    ({"footstep": {"transition": {"spread": "wide"}}}, "footstep.transition.spread",
     ("number", "wide")),
    ({"optimise": "yes"}, "optimise", ("true or false",)),
    ({"dt": True}, "dt", ("number",)),
    ({"seed": {"arc_heights": [0.1, "x"]}}, "seed.arc_heights[1]", ("number",)),
    ({"scp": 3}, "scp", ("mapping",)),
    ({"scp": {"solver": 1}}, "scp.solver", ("string",)),
])
def test_mistakes_name_the_key(data, field: str, words: tuple[str, ...]) -> None:
    with pytest.raises(ConfigError) as info:
        config_from_dict(PipelineConfig, data, "planner.yaml")
    err = info.value
    assert (err.source, err.field) == ("planner.yaml", field), str(err)
    assert str(err) == f"planner.yaml: {field}: {err.reason}" and "\n" not in str(err)
    for word in words:
        assert word in err.reason, f"{err.reason!r} lacks {word!r}"


def test_load_config_file(tmp_path: Path) -> None:
    path = tmp_path / "planner.yaml"
    path.write_text("footstep:\n  max_expansions: 20\n  transition: {samples: 12}\n"
                    "scp: {radius_velocity: .inf}\ndt: 0.25\n")
    cfg = load_config(path, PipelineConfig)
    assert (cfg.footstep.max_expansions, cfg.footstep.transition.samples, cfg.dt) == (20, 12,
                                                                                      0.25)
    (tmp_path / "empty.yaml").write_text("")
    assert load_config(tmp_path / "empty.yaml", PipelineConfig) == PipelineConfig()
    (tmp_path / "broken.yaml").write_text("footstep: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(tmp_path / "broken.yaml", PipelineConfig)


@pytest.fixture
def stuck(tmp_path: Path) -> Path:
    path = tmp_path / "stuck.yaml"
    path.write_text(yaml.safe_dump(SHAFT, sort_keys=False))
    return path


def test_plan_records_provenance_and_reads_config(tmp_path: Path, stuck: Path) -> None:
    (tmp_path / "planner.yaml").write_text("footstep: {max_expansions: 7, seed: 4}\n"
                                           "seed: {ompl_time: 0.25}\n")
    proc = run_rbp("plan", str(stuck), "-o", "p.json", "--config", "planner.yaml",
                   "--no-pictures", cwd=tmp_path)
    assert proc.returncode == 1, f"exit {proc.returncode}\n{proc.stderr}"  # no route there
    plan = json.loads((tmp_path / "p.json").read_text())
    validate(plan)
    prov = plan["provenance"]
    expected = dataclasses.replace(
        PipelineConfig(), footstep=FootstepConfig(max_expansions=7, seed=4),
        seed=dataclasses.replace(PipelineConfig().seed, ompl_time=0.25))
    assert prov["config"] == config_to_dict(expected), prov["config"]
    assert prov["seed"] == 4 and prov["planner"] == "rbp" and prov["motion"] is True
    assert prov["command"] == (f"rbp plan {stuck} -o p.json --config planner.yaml "
                               "--no-pictures"), prov["command"]
    assert prov["rbp_version"] and prov["scenario_source"] == str(stuck)
    # what it ran under (issue 32): the kernel threads, the cores and the load
    assert 1 <= prov["threads"] <= prov["cores"] == os.cpu_count(), prov
    assert prov["load"] is None or prov["load"] >= 0, prov
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.json", "planner.yaml",
                                                          "stuck.yaml"]


def test_flags_override_the_config_file(tmp_path: Path, stuck: Path) -> None:
    (tmp_path / "planner.yaml").write_text("footstep: {max_expansions: 7, seed: 4}\n")
    proc = run_rbp("plan", str(stuck), "-o", "p.json", "--config", "planner.yaml", "--seed",
                   "9", "--no-pictures", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    footstep = json.loads((tmp_path / "p.json").read_text())["provenance"]["config"]["footstep"]
    assert (footstep["seed"], footstep["max_expansions"]) == (9, 7), footstep


@pytest.mark.parametrize("text, field", [
    ("footstep: {max_expansion: 5}\n", "footstep.max_expansion"),
    ("scp: {max_iterations: ten}\n", "scp.max_iterations"),
    ("colour: red\n", "colour"),
])
def test_bad_config_exits_2_naming_file_and_key(tmp_path: Path, stuck: Path, text: str,
                                                field: str) -> None:
    (tmp_path / "planner.yaml").write_text(text)
    proc = run_rbp("plan", str(stuck), "-o", "p.json", "--config", "planner.yaml", cwd=tmp_path)
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stderr}"
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: planner.yaml: {field}:"), proc.stderr
    assert not (tmp_path / "p.json").exists()


def test_from_plan_repeats_the_plan_exactly(tmp_path: Path) -> None:
    first = run_rbp("plan", "demo-crevasse", "-o", "a.json", "--seed", "3", "--no-scp",
                    "--no-pictures", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    again = run_rbp("plan", "--from-plan", "a.json", "-o", "b.json", "--no-pictures",
                    cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert b["provenance"]["config"] == a["provenance"]["config"]
    assert b["provenance"]["seed"] == 3 and b["scenario"] == a["scenario"]
    footsteps_a = [(p["kind"], p["stance"], p.get("to_anchor")) for p in a["phases"]]
    footsteps_b = [(p["kind"], p["stance"], p.get("to_anchor")) for p in b["phases"]]
    assert footsteps_b == footsteps_a, "the repeated plan takes other footsteps"
    poses_a = [s["pose"] for p in a["phases"] for s in p["steps"]]
    poses_b = [s["pose"] for p in b["phases"] for s in p["steps"]]
    assert poses_b == poses_a, "the repeated plan's poses differ"
    assert b["p_path"] == a["p_path"], f"p_path {b['p_path']!r} != {a['p_path']!r}"


def test_from_plan_without_provenance_is_refused(tmp_path: Path) -> None:
    proc = run_rbp("plan", "demo-crevasse", "-o", "a.json", "--footsteps-only",
                   "--max-expansions", "3", "--no-pictures", cwd=tmp_path)
    plan = json.loads((tmp_path / "a.json").read_text())
    del plan["provenance"]
    (tmp_path / "old.json").write_text(json.dumps(plan))
    proc = run_rbp("plan", "--from-plan", "old.json", "-o", "b.json", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: old.json: provenance: missing"), proc.stderr
    both = run_rbp("plan", "demo-crevasse", "--from-plan", "a.json", "-o", "b.json",
                   cwd=tmp_path)
    assert both.returncode == 2 and len(both.stderr.strip().splitlines()) == 1, both.stderr


def test_provenance_records_the_threads_and_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """A plan records the threads its kernels ran on (RBP_THREADS here) and the load."""
    from rb_drake.scenario import bundled_caves, load_scenario
    from rbp.commands.plan import provenance

    monkeypatch.setenv("RBP_THREADS", "1")
    scn = load_scenario(bundled_caves()["demo-shaft"])
    prov = provenance(scn, "rbp", PipelineConfig(), True, ["plan", "demo-shaft"])
    assert (prov.threads, prov.cores) == (1, os.cpu_count()), prov
    assert prov.load is None or prov.load >= 0, prov
    assert {"threads", "cores", "load"} <= set(prov.to_dict()), prov.to_dict()
