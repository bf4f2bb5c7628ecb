"""Every picture the command line draws fits its figure (issue 32).

The commands run in this process (`rbp.cli.main`) with `rb_drake.files.atomic_save_figure`
wrapped to keep each Figure it saves, so the test sees exactly the pictures a user gets: a
bundled success (`rbp plan demo-shaft`, budget-capped so that it takes seconds, with a phase's
Fig. 6), two failures (a budget stop and a proof of no route, each with its search picture),
the rig (`rbp plan rig` with its animation's first and last frames, `rbp rig-report`),
`rbp scenario show` and `rbp demo`. For each figure, after a draw:
every visible text and legend lies inside the figure (a pixel of tolerance), no legend covers
an axis label, a title or a tick label, and no two titles or labels overlap. The comparison's
histogram (experiments.baseline_comparison) is checked on made-up records: its bars add up to
the counts its legend gives.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.text import Text
from matplotlib.transforms import Bbox

import rb_drake.files
from rbp.cli import main

TOLERANCE = 1.5  # pixels


@pytest.fixture
def capture(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, Figure]]:
    """The (path, figure) pairs the command saves."""
    saved: list[tuple[str, Figure]] = []
    save = rb_drake.files.atomic_save_figure

    def keep(fig: Figure, path: str | Path, **kwargs: Any) -> Path:
        saved.append((str(path), fig))
        return save(fig, path, **kwargs)

    monkeypatch.setattr(rb_drake.files, "atomic_save_figure", keep)
    return saved


def _drawn_tick_labels(fig: Figure) -> list[Text]:
    labels = []
    for ax in fig.axes:
        if not ax.get_visible() or not ax.axison:
            continue
        for axis in (ax.xaxis, ax.yaxis):
            for tick in axis._update_ticks():  # the ticks drawn (the others are stale)
                labels += [t for t in (tick.label1, tick.label2)
                           if t.get_visible() and t.get_text()]
    return labels


def _texts(fig: Figure) -> list[Text]:
    """Visible, non-empty texts outside tick labels (those come from _drawn_tick_labels)."""
    ticks = {id(t) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
             for tick in axis.get_major_ticks() + axis.get_minor_ticks()
             for t in (tick.label1, tick.label2)}
    return [t for t in fig.findobj(Text)
            if id(t) not in ticks and t.get_visible() and t.get_text().strip()
            and _shown(t)]


def _shown(t: Text) -> bool:
    return t.axes is None or t.axes.get_visible()


def _legends(fig: Figure) -> list[Legend]:
    return [lg for lg in fig.findobj(Legend) if lg.get_visible()]


def _overlap(a: Bbox, b: Bbox) -> bool:
    return (min(a.x1, b.x1) - max(a.x0, b.x0) > TOLERANCE
            and min(a.y1, b.y1) - max(a.y0, b.y0) > TOLERANCE)


def problems(fig: Figure) -> list[str]:
    """What is clipped or covered in the figure, one line each."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    box = fig.bbox
    found = []

    def inside(name: str, extent: Bbox) -> None:
        if (extent.x0 < box.x0 - TOLERANCE or extent.y0 < box.y0 - TOLERANCE
                or extent.x1 > box.x1 + TOLERANCE or extent.y1 > box.y1 + TOLERANCE):
            found.append(f"{name} {extent.bounds} is outside the figure {box.bounds}")

    texts = _texts(fig)
    ticks = _drawn_tick_labels(fig)
    legends = _legends(fig)
    in_legend = {id(t) for lg in legends for t in lg.findobj(Text)}
    for t in texts + ticks:
        inside(f"text {t.get_text()!r}", t.get_window_extent(renderer))
    for lg in legends:
        inside("legend", lg.get_window_extent(renderer))
    labels = [t for t in texts if id(t) not in in_legend]
    for lg in legends:
        extent = lg.get_window_extent(renderer)
        for t in labels + ticks:
            if _overlap(extent, t.get_window_extent(renderer)):
                found.append(f"a legend covers {t.get_text()!r}")
    for ax in fig.axes:  # an axis's tick labels apart from one another
        for axis in (ax.xaxis, ax.yaxis):
            mine = {id(lb) for tick in axis._update_ticks() for lb in (tick.label1, tick.label2)}
            boxes = [(t.get_window_extent(renderer), t.get_text()) for t in ticks
                     if id(t) in mine]
            for i, (a, text_a) in enumerate(boxes):
                for b, text_b in boxes[i + 1:]:
                    if _overlap(a, b):
                        found.append(f"tick labels {text_a!r} and {text_b!r} overlap")
    titles = [t for t in labels if t.get_text() and not _in_data(t)]
    for i, a in enumerate(titles):
        for b in titles[i + 1:]:
            if _overlap(a.get_window_extent(renderer), b.get_window_extent(renderer)):
                found.append(f"{a.get_text()!r} overlaps {b.get_text()!r}")
    return found


def _in_data(t: Text) -> bool:
    """Annotations placed in the data (boom labels) may overlap one another."""
    return (t.axes is not None and t.get_transform() == t.axes.transData) or (
        type(t).__name__ == "Annotation")


def all_text(fig: Figure) -> str:
    return "\n".join(t.get_text() for t in fig.findobj(Text))


def check_all(saved: list[tuple[str, Figure]]) -> None:
    assert saved, "no picture was drawn"
    bad = {path: p for path, fig in saved if (p := problems(fig))}
    assert not bad, bad
    for path, fig in saved:
        text = all_text(fig)
        assert "0.0e+00" not in text, f"{path}: a probability printed as 1 - 0"
        assert not re.search(r"stance 0 of 0\b", text), f"{path}: {text}"


def run(*argv: str) -> int:
    return main(list(argv))


def test_success_pictures(capture, tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    assert run("plan", "demo-shaft", "--max-expansions", "100", "-q", "--phase-figure", "0",
               "-o", str(out)) == 0
    assert [Path(p).name for p, _ in capture] == ["plan.png", "plan-phase0.png"]
    check_all(capture)
    snapshots = all_text(capture[0][1])
    # The panels say which pose their P is at: the stance's first pose (for the first, the
    # start pose, as `rbp scenario show` gives it) and the drawn one (its release pose).
    assert "stance 1 of 8" in snapshots, snapshots
    from rb_drake.draw import scenario_figure
    from rbp.commands.common import load_scenario_spec

    cave = all_text(scenario_figure(load_scenario_spec("demo-shaft")))
    start = re.search(r"start pose: P\(all grasps hold\) = (.+?)  ", cave)
    assert start, cave
    assert f"P {start.group(1)} → " in snapshots, (start.group(1), snapshots)


def test_a_tall_cave_fits_its_pictures(capture, tmp_path: Path) -> None:
    """A 30 m shaft's search picture had its title cut off at the figure's edge (centred on the
    narrow axes), and its plan picture's x tick labels ran together ("-10 1")."""
    assert run("scenario", "generate", "--kind", "shaft", "--seed", "7", "--length", "30",
               "30", "-o", str(tmp_path / "tall.yaml")) == 0
    assert run("plan", str(tmp_path / "tall.yaml"), "--footsteps-only", "-q",
               "--max-expansions", "3", "-o", str(tmp_path / "plan.json")) == 1
    assert [Path(p).name for p, _ in capture] == ["plan.png", "plan-search.png"]
    check_all(capture)


@pytest.mark.parametrize("flags", [["--max-expansions", "3"], []],
                         ids=["budget", "noroute"])
def test_failure_pictures(capture, tmp_path: Path, flags: list[str]) -> None:
    cave = "demo-shaft" if flags else "blocked-shaft"
    out = tmp_path / "plan.json"
    assert run("plan", cave, "--footsteps-only", "-q", *flags, "-o", str(out)) == 1
    assert [Path(p).name for p, _ in capture] == ["plan.png", "plan-search.png"]
    check_all(capture)
    import json

    reason = json.loads(out.read_text())["reason"]
    stated = re.search(r"nearest stance reached is ([0-9.]+) m from the goal", reason)
    assert stated, reason
    legend = all_text(capture[1][1])
    # one named distance: the search picture gives the message's number
    assert f"{stated.group(1)} m" in legend, (reason, legend)


def test_rig_pictures(capture, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import planning.figures

    make = planning.figures.animation_figure
    calls: list[tuple[Any, ...]] = []

    def keep(*args: Any, **kwargs: Any):
        calls.append(args)
        return make(*args, **kwargs)

    monkeypatch.setattr(planning.figures, "animation_figure", keep)
    animation = tmp_path / "r.gif"
    assert run("plan", "rig", "-q", "--phase-figure", "0", "--animate", str(animation),
               "-o", str(tmp_path / "r.json")) == 0
    assert [Path(p).name for p, _ in capture] == ["r.png", "r-phase0.png"]
    assert animation.stat().st_size > 1000 and len(calls) == 1
    # the animation's first and last frames, drawn again as the writer drew them
    first, _, _ = make(*calls[0])
    last, draw_frame, count = make(*calls[0])
    draw_frame(count - 1)
    check_all([*capture, ("animation, first frame", first), ("animation, last frame", last)])
    assert "stance 1 of 1" in all_text(capture[0][1])


def test_rig_report_picture(capture, tmp_path: Path) -> None:
    plan, log = tmp_path / "r.json", tmp_path / "rig.lcm"
    assert run("plan", "rig", "-q", "--no-pictures", "-o", str(plan)) == 0
    assert run("rig-run", str(plan), "--phase", "0", "--sim-rig", "--log", str(log)) == 0
    assert run("rig-report", str(log), "-o", str(tmp_path / "report.png")) == 0
    assert [Path(p).name for p, _ in capture] == ["report.png"]
    check_all(capture)


def test_demo_picture(capture, tmp_path: Path) -> None:
    assert run("demo", "--no-plan", "--out", str(tmp_path)) == 0
    assert [Path(p).name for p, _ in capture] == ["cave.png"]
    check_all(capture)


@pytest.mark.parametrize("cave", ["demo-shaft", "demo-crevasse", "rockfall-3", "rig"])
def test_scenario_show(capture, tmp_path: Path, cave: str) -> None:
    assert run("scenario", "show", cave, "-o", str(tmp_path / "cave.png")) == 0
    check_all(capture)
    legend = all_text(capture[0][1])
    assert "held" in legend and "normal" in legend, legend  # the red ticks explained


def test_comparison_histogram_counts() -> None:
    from experiments.baseline_comparison import baseline_figure

    def record(rbp: float | None, naive: float | None) -> dict[str, Any]:
        def one(p: float | None) -> dict[str, Any]:
            return {"success": p is not None, "p_path": p, "p_grasps": p}
        return {"result": {"rbp": one(rbp), "naive": one(naive)}}

    records = [record(0.95, None), record(0.97, 0.5), record(0.91, None), record(None, 0.2),
               record(0.99, None), record(0.93, None), record(0.96, None), record(0.92, None)]
    fig = baseline_figure(records, ["rbp", "naive"])
    assert not problems(fig), problems(fig)
    hist = fig.axes[0]
    for planner, plans, failed in (("rbp", 7, 1), ("naive", 2, 6)):
        bars = [c for c in hist.containers if c.get_label().startswith(planner)]
        heights = [sum(r.get_height() for r in c) for c in bars]
        label = " ".join(c.get_label() for c in bars)
        assert f"{plans} plans" in label and f"{failed} failed" in label, label
        assert sorted(heights) == sorted([plans, failed]), (planner, heights, label)


def test_picture_suffix_name_and_sigterm(tmp_path: Path, capsys) -> None:
    """A picture's suffix must be a format matplotlib writes, checked before the work (.xyz
    ended in matplotlib's ValueError traceback); a scenario's name is at most 200 characters
    (999,000 took minutes and 1 GB to draw in a title) and titles show 80; SIGTERM during a
    write removes the temporary file, as Ctrl-C does."""
    import os
    import signal

    import yaml

    from rb_drake.draw import title_name
    from rb_drake.files import atomic_write
    from rbp.commands.common import Terminated, clean_interrupts

    for argv in (["scenario", "show", "demo-shaft"], ["rig-report", str(tmp_path / "no.lcm")]):
        capsys.readouterr()
        assert run(*argv, "-o", str(tmp_path / "x.xyz")) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and "x.xyz: -o: a picture's suffix must be one of" in err[0], err
    assert not list(tmp_path.glob("x.*"))

    scenario = Path(__file__).resolve().parents[1] / "rb_drake/data/caves/demo-shaft.yaml"
    data = yaml.safe_load(scenario.read_text())
    data["name"] = "n" * 201
    long_name = tmp_path / "long.yaml"
    long_name.write_text(yaml.safe_dump(data))
    assert run("scenario", "show", str(long_name), "-o", str(tmp_path / "c.png")) == 2
    assert "name: 201 characters; at most 200" in capsys.readouterr().err
    assert title_name("n" * 200) == "n" * 79 + "…" and title_name("short") == "short"

    def killed(f) -> None:
        f.write(b"half a picture")
        os.kill(os.getpid(), signal.SIGTERM)

    with pytest.raises(Terminated), clean_interrupts():
        atomic_write(tmp_path / "pic.png", killed)
    assert not list(tmp_path.glob("*.png*")) and not list(tmp_path.glob(".pic.png.*"))
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, "the handler is put back"


HOSTILE_NAME = "$x^{$ 洞窟\t😀\r$\\frac{"  # mathtext, glyphs the font lacks, control characters


def test_hostile_names_draw_quietly(tmp_path: Path) -> None:
    """A scenario's name with `$...$` ended every picture in mathtext's traceback (scenario
    show, plan, demo, rig-report), and one the font lacks glyphs for printed a UserWarning per
    glyph: each picture is drawn now with nothing on stderr, as is `simulate --html`'s replay."""
    import json

    import yaml

    from rb_drake.scenario import bundled_caves
    from tests.cli_helpers import run_rbp

    def quiet(*args: str, status: int = 0) -> None:
        result = run_rbp(*args, cwd=tmp_path)
        assert result.returncode == status and not result.stderr, (args, result.stderr[-2000:])

    cave = yaml.safe_load(bundled_caves()["demo-shaft"].read_text())
    cave["name"] = HOSTILE_NAME
    (tmp_path / "cave.yaml").write_text(yaml.safe_dump(cave, allow_unicode=True))
    quiet("scenario", "show", "cave.yaml", "-o", "cave.png")
    quiet("demo", "--scenario", "cave.yaml", "--no-plan", "--out", "demo")
    quiet("plan", "cave.yaml", "--footsteps-only", "-q", "--max-expansions", "3", "-o", "p.json",
          status=1)  # the snapshots and the search picture
    quiet("plan", "rig", "-q", "--no-pictures", "-o", "r.json")
    # Drake's "INFO:drake:Meshcat listening for connections at ..." was printed on stderr
    quiet("simulate", "--trials", "0", "--html", "r.html", "r.json")
    plan = json.loads((tmp_path / "r.json").read_text())
    plan["scenario"]["name"] = HOSTILE_NAME
    (tmp_path / "r.json").write_text(json.dumps(plan))
    quiet("rig-run", "r.json", "--phase", "0", "--sim-rig", "--log", "rig.lcm")
    quiet("rig-report", "rig.lcm", "-o", "report.png")
    assert all((tmp_path / p).stat().st_size > 1000
               for p in ("cave.png", "demo/cave.png", "p.png", "p-search.png", "report.png"))
