"""Probe 22: the filesystem and the process environment around every command (file names that
are not UTF-8, full disks, signals, standard streams, folders that go away). Each test shows
the command refusing in one line, or doing its work, where it once ended in a traceback or
wrote an output its own readers refuse."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from cli_helpers import ROOT, one_error_line, run_rbp

from rb_drake.errors import utf8_text

DEMO = ROOT / "rb_drake" / "data" / "caves" / "demo-shaft.yaml"
GEOJSON = ROOT / "rb_drake" / "data" / "terrain" / "lava-tube-shaft.geojson"
NOT_UTF8 = os.fsdecode(b"cave\xff\xfe")  # a file name's bytes as argv gives them to Python


def test_utf8_text_escapes_only_what_utf8_cannot_hold() -> None:
    assert utf8_text("shaft é洞") == "shaft é洞", "UTF-8 text must stay as it is"
    assert utf8_text(NOT_UTF8) == "cave\\udcff\\udcfe", utf8_text(NOT_UTF8)
    utf8_text(NOT_UTF8).encode("utf-8")  # never raises


def test_a_plan_of_a_file_named_in_bytes_reads_back(tmp_path: Path) -> None:
    """The plan's provenance held the name's lone surrogates: `rbp check` refused the plan
    `rbp plan` had just written (`provenance.command: a lone surrogate`), and so did
    `--from-plan`."""
    shutil.copy(DEMO, tmp_path / f"{NOT_UTF8}.yaml")
    made = run_rbp("plan", f"{NOT_UTF8}.yaml", "--footsteps-only", "--no-pictures", "--quiet",
                   "-o", f"{NOT_UTF8}.json", cwd=tmp_path)
    assert made.returncode == 0, made.stderr[-600:]
    plan = json.loads((tmp_path / f"{NOT_UTF8}.json").read_bytes())
    recorded = plan["provenance"]
    assert "cave\\udcff\\udcfe.yaml" in recorded["command"], recorded["command"]
    assert recorded["scenario_source"] == "cave\\udcff\\udcfe.yaml", recorded
    checked = run_rbp("check", "-q", f"{NOT_UTF8}.json", cwd=tmp_path)
    assert checked.returncode == 0, f"rbp check refused rbp plan's plan: {checked.stderr!r}"


def test_simulate_json_names_a_plan_named_in_bytes_as_utf8(tmp_path: Path) -> None:
    """`rbp simulate --json` wrote the plan's name with its lone surrogates (\\udcff in JSON, no
    UTF-8 text)."""
    plan = tmp_path / f"{NOT_UTF8}.json"
    shutil.copy(ROOT / "tests" / "data" / "golden" / "demo-shaft-current.json", plan)
    sim = run_rbp("simulate", plan.name, "--trials", "0", "--json", "sim.json", cwd=tmp_path)
    assert sim.returncode == 0, sim.stderr[-600:]
    raw = (tmp_path / "sim.json").read_text(encoding="utf-8")
    assert json.loads(raw)["plan"] == "cave\\udcff\\udcfe.json", raw[:200]


def test_import_of_a_file_named_in_bytes_writes_a_cave_that_reads_back(tmp_path: Path) -> None:
    """`rbp scenario import` of a file whose name is not UTF-8 ended in a UnicodeEncodeError's
    traceback (its command line, in the cave's first line, and its default name)."""
    pytest.importorskip("shapely")
    shutil.copy(GEOJSON, tmp_path / f"{NOT_UTF8}.geojson")
    made = run_rbp("scenario", "import", f"{NOT_UTF8}.geojson", "-o", "cave.yaml", cwd=tmp_path)
    assert made.returncode == 0 and "Traceback" not in made.stderr, made.stderr[-800:]
    text = (tmp_path / "cave.yaml").read_text(encoding="utf-8")
    assert "name: cave\\udcff\\udcfe" in text, text[:300]
    checked = run_rbp("scenario", "check", "cave.yaml", cwd=tmp_path)
    assert checked.returncode == 0, checked.stderr


def test_import_refuses_a_name_in_bytes(tmp_path: Path) -> None:
    """`--name` of bytes that are not UTF-8 was the same traceback; a name is text."""
    pytest.importorskip("shapely")
    result = run_rbp("scenario", "import", str(GEOJSON), "--name", NOT_UTF8, "-o", "cave.yaml",
                     cwd=tmp_path)
    one_error_line(result, "--name", "not UTF-8 text", "cave\\udcff\\udcfe")
    assert not (tmp_path / "cave.yaml").exists(), "a refused import wrote its cave"
