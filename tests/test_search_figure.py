"""The picture of a failed footstep search (planning.figures.search_figure)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planning.figures import STOP_REASONS, search_figure
from planning.footsteps import FootstepConfig, plan_footsteps
from rb_drake.files import atomic_save_figure


@pytest.fixture(scope="module")
def failed(shaft):
    # The sampled search expands stances before it gives up (the complete one proves at once
    # that no stance can hold this cave's goal, and so records none).
    fp = plan_footsteps(shaft, FootstepConfig(search="sampled", max_expansions=5))
    assert not fp.success, "the four-anchor test shaft has no route"
    return fp


def legend_texts(fig) -> list[str]:
    """The legend's entries (below the cave, in the figure), each on one line."""
    legends = fig.legends + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    return [t.get_text().replace("\n", " ") for legend in legends for t in legend.texts]


def test_search_picture_is_written(shaft, failed, tmp_path: Path) -> None:
    fig = search_figure(shaft, failed)
    texts = legend_texts(fig)
    assert any(STOP_REASONS[failed.stop] in t for t in texts), f"{failed.stop!r}: {texts}"
    assert any(t.startswith("nearest stance reached: ") for t in texts), texts
    assert any(t.startswith("goal, within ") for t in texts), texts
    path = atomic_save_figure(fig, tmp_path / "search.png", dpi=60)
    assert path.stat().st_size > 1000, f"{path} is tiny"


@pytest.mark.parametrize("stop", ["budget", "exhausted", "noroute"])
def test_legend_says_why_it_stopped(shaft, failed, stop: str) -> None:
    texts = legend_texts(search_figure(shaft, failed._replace(stop=stop)))
    assert any(t.startswith(f"search {STOP_REASONS[stop]}") for t in texts), texts
    if stop == "noroute":
        assert any("2 cm / 2.5 deg" in t for t in texts), texts


def test_missing_exploration_is_tolerated(shaft, failed, tmp_path: Path) -> None:
    fp = failed._replace(explored=None, frontier=None, stop="")
    fig = search_figure(shaft, fp)
    assert any("start" in t for t in legend_texts(fig)), legend_texts(fig)
    assert atomic_save_figure(fig, tmp_path / "s.png", dpi=60).stat().st_size > 1000
    nearest = min(failed.explored, key=lambda e: e.goal_distance)
    assert np.isfinite(nearest.goal_distance)
