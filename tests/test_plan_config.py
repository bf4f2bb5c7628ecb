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


def _config_classes(cls: type, seen: dict[str, type]) -> dict[str, type]:
    """Every configuration dataclass reachable from `cls` (nested, also as `X | None`)."""
    import typing

    seen[cls.__name__] = cls
    for hint in typing.get_type_hints(cls).values():
        for tp in (hint, *typing.get_args(hint)):
            if dataclasses.is_dataclass(tp) and tp.__name__ not in seen:
                _config_classes(tp, seen)  # type: ignore[arg-type]
    return seen


def test_every_field_has_a_range_and_the_defaults_are_in_it() -> None:
    """planning.config_ranges states every number's range and every word's choices, so that
    nothing the reader accepts can crash or hang the planner; the defaults lie within them."""
    from planning.complete_config import AnytimeConfig
    from planning.config_ranges import FIELDS, field_problem
    from planning.route_repair import RepairConfig
    from planning.segmented import SegmentConfig

    classes = _config_classes(PipelineConfig, {})
    assert set(classes) == set(FIELDS), set(classes) ^ set(FIELDS)
    for name, cls in classes.items():
        unbounded = [f.name for f in dataclasses.fields(cls)
                     if f.type not in ("bool", "LatticeConfig", "TransitionConfig",
                                       "SeedConfig", "ScpConfig", "FootstepConfig")
                     and not f.type.endswith("Config | None")
                     and f.name not in FIELDS[name]]
        assert not unbounded, f"{name}: fields without a range: {unbounded}"
        assert set(FIELDS[name]) <= {f.name for f in dataclasses.fields(cls)}, name
    defaults = [PipelineConfig(), AnytimeConfig(), RepairConfig(), SegmentConfig()]
    for config in defaults:
        for cfg in [config, *(getattr(config, f.name) for f in dataclasses.fields(config))]:
            if dataclasses.is_dataclass(cfg):
                for f in dataclasses.fields(cfg):
                    assert not field_problem(type(cfg), f.name, getattr(cfg, f.name)), \
                        (type(cfg).__name__, f.name)
    assert config_from_dict(PipelineConfig, config_to_dict(PipelineConfig()), "p.yaml") == \
        PipelineConfig()


def test_docs_list_every_range() -> None:
    from planning.config_ranges import range_lines

    docs = (Path(__file__).resolve().parents[1] / "docs" / "formats.md").read_text()
    missing = [line for line in range_lines() if line not in docs]
    assert not missing, "docs/formats.md lacks these rows:\n" + "\n".join(missing)


# Values the reader took that then crashed or hung `rbp plan` (the hostile probe of session 28)
@pytest.mark.parametrize("data, field, words", [
    ({"footstep": {"expansions_per_metre": "inf"}}, "footstep.expansions_per_metre",
     "from 0 to 1,000,000"),
    ({"seed": {"step": 0.0}}, "seed.step", "from 0.005 to 1 m, got 0.0"),
    ({"seed": {"step": 1.0e-300}}, "seed.step", "from 0.005"),
    ({"seed": {"step": 0.001}}, "seed.step", "from 0.005"),  # 2.4 GB and minutes before
    ({"seed": {"local_samples": 10_000}}, "seed.local_samples", "from 1 to 100"),  # 36 GiB
    ({"seed": {"step": -0.02}}, "seed.step", "from 0.005"),
    ({"seed": {"turn_step": "inf"}}, "seed.turn_step", "got inf"),
    ({"seed": {"local_samples": 0}}, "seed.local_samples", "whole number from 1"),
    ({"seed": {"arc_heights": ["inf"]}}, "seed.arc_heights", "got inf"),
    ({"seed": {"arc_heights": []}}, "seed.arc_heights", "1 to 32 numbers"),
    ({"footstep": {"goal_samples": -5}}, "footstep.goal_samples", "got -5"),
    ({"footstep": {"goal_samples": 10**12}}, "footstep.goal_samples", "to 100,000"),
    ({"footstep": {"transition": {"release_candidates": 0}}},
     "footstep.transition.release_candidates", "got 0"),
    ({"footstep": {"transition": {"elite": -3}}}, "footstep.transition.elite", "got -3"),
    ({"footstep": {"transition": {"phi_range": "inf"}}}, "footstep.transition.phi_range",
     "to 3.1416 rad"),
    ({"footstep": {"transition": {"spread": -1.0}}}, "footstep.transition.spread", "got -1.0"),
    ({"footstep": {"segments": {"commit": 1e-300}}}, "footstep.segments.commit", "from 0.1"),
    ({"footstep": {"polish_rounds": 10**12}}, "footstep.polish_rounds", "from 0 to 1000"),
    ({"footstep": {"heuristic_weight": "inf"}}, "footstep.heuristic_weight", "got inf"),
    ({"footstep": {"min_success": 1.0}}, "footstep.min_success", "below 1"),
    ({"footstep": {"anytime": {"weights": [5.0, 0.0]}}}, "footstep.anytime.weights", "above 0"),
    ({"footstep": {"search": "greedy"}}, "footstep.search", "one of hybrid, complete, sampled"),
    ({"scp": {"robustness_weight": "inf"}}, "scp.robustness_weight", "got inf"),
    ({"scp": {"solver": "foo"}}, "scp.solver", "one of clarabel, osqp, got 'foo'"),
    ({"dt": 1e-300}, "dt", "from 0.25 to 60 s"),
])
def test_values_outside_their_range_refused_at_reading(data, field: str, words: str) -> None:
    for prefix in ("", "provenance.config"):  # a --config file, a plan's provenance
        with pytest.raises(ConfigError) as info:
            config_from_dict(PipelineConfig, data, "planner.yaml", prefix=prefix)
        where = f"{prefix}.{field}" if prefix else field
        assert info.value.field == where and words in info.value.reason, str(info.value)
    assert config_from_dict(PipelineConfig, {"scp": {"radius_velocity": "inf"}},
                            "p.yaml").scp.radius_velocity == float("inf")  # documented: none


def test_unknown_keys_found_without_the_planner_as_its_classes_find_them(tmp_path) -> None:
    """`rbp plan` refuses a misspelt configuration key before importing the planner, from
    planning.config_ranges alone: each section's keys are its class's fields, and a misspelt
    key at every depth gets the classes' own message."""
    import dataclasses

    from planning.complete_config import AnytimeConfig
    from planning.config_ranges import SECTIONS, section_keys, unknown_key
    from planning.lattice import LatticeConfig
    from planning.route_repair import RepairConfig
    from planning.seed_common import SeedConfig
    from planning.segmented import SegmentConfig
    from planning.transition import TransitionConfig

    classes = {c.__name__: c for c in (PipelineConfig, FootstepConfig, LatticeConfig,
                                       AnytimeConfig, RepairConfig, SegmentConfig,
                                       TransitionConfig, SeedConfig, ScpConfig)}
    assert set(classes) == set(SECTIONS), "a configuration class without its section here"
    for name, section in SECTIONS.items():
        fields = sorted(f.name for f in dataclasses.fields(classes[name]) if f.init)
        assert section_keys(section) == fields, f"{name}: keys known without the planner"
        data: dict = {"speling": 1}
        for part in reversed(section.split(".")[:-1]):
            data = {part: data}
        with pytest.raises(ConfigError) as refused:
            config_from_dict(PipelineConfig, data, "c.yaml")
        assert unknown_key(data) == (refused.value.field, refused.value.reason), section
    assert unknown_key({"footstep": {"lattice": {"position_step": 0.02}}, "seed": {}}) is None
    config = tmp_path / "c.yaml"
    config.write_text("footstep:\n  anytime:\n    improve_factr: 2\n")
    result = run_rbp("plan", "demo-shaft", "--config", str(config), "-o", "p.json",
                     cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "footstep.anytime.improve_factr: unknown key" in lines[0], lines[0]


@pytest.mark.parametrize("data", [{"dt": -1.0, "zzz": 1}, {"footstep": "x", "zzz": 1},
                                  {"footstep": {"max_expansions": "abc", "lattice": {"zzz": 1}}}])
def test_a_file_s_keys_are_checked_before_its_values_by_either_reader(data) -> None:
    """`rbp plan` checks a configuration's keys before its imports; the full reader (the API,
    --from-plan) checks a whole file's keys before its values too, so both name the same first
    problem (an earlier bad value was named by one, a later unknown key by the other)."""
    from planning.config_ranges import unknown_key

    with pytest.raises(ConfigError) as refused:
        config_from_dict(PipelineConfig, data, "c.yaml")
    assert (refused.value.field, refused.value.reason) == unknown_key(data), refused.value
