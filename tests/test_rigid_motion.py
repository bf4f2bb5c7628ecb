"""experiments.rigid_motion: a cave moved rigidly by less than a lattice cell keeps its physics
(only where the lattice falls changes), and the experiment records each copy's answer."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from experiments import rigid_motion
from experiments.common import make_cave
from rb_drake.kernel.scoring import score_poses


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_moved_cave_scores_every_pose_alike(seed: int) -> None:
    cave = make_cave("shaft", 71, (4.5, 5.0))
    rng = np.random.default_rng(seed)
    angle, shift = rigid_motion.rigid_motion(rng)
    assert abs(math.degrees(angle)) < 2.5 and np.all(np.abs(shift) < 0.02), (angle, shift)
    moved = rigid_motion.moved_scenario(cave, angle, shift)
    c, s = math.cos(angle), math.sin(angle)
    # poses about the start: feasible and infeasible ones, moved as the cave was
    poses = np.asarray(cave.start_pose, dtype=float) + rng.normal(0.0, [0.1, 0.1, 0.1], (64, 3))
    moved_poses = np.column_stack([c * poses[:, 0] - s * poses[:, 1] + shift[0],
                                   s * poses[:, 0] + c * poses[:, 1] + shift[1],
                                   poses[:, 2] + angle])
    before = score_poses(cave, cave.stance(cave.start_stance), poses)
    after = score_poses(moved, moved.stance(moved.start_stance), moved_poses)
    assert before.feasible.any() and not before.feasible.all(), "pick poses of both kinds"
    np.testing.assert_array_equal(after.feasible, before.feasible)
    both = before.feasible
    np.testing.assert_allclose(after.robustness[both], before.robustness[both], rtol=1e-9,
                               atol=1e-9, err_msg="a moved pose's robustness changed")
    np.testing.assert_allclose(np.linalg.norm(moved.gravity_vector),
                               np.linalg.norm(cave.gravity_vector), rtol=1e-12)


def test_the_experiment_records_every_copy(tmp_path: Path) -> None:
    out = tmp_path / "rm.json"
    assert rigid_motion.main(["--seeds", "51", "--motions", "2", "--variants", "lattice",
                              "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    runs = data["caves"][0]["lattice"]
    assert len(runs) == 3 and len(data["caves"][0]["motions"]) == 3, data["caves"][0]
    assert data["caves"][0]["motions"][0] == [0.0, 0.0, 0.0], "the first copy is the cave"
    assert data["summary"]["lattice"]["runs"] == 3
    stable = data["summary"]["lattice"]["stable"] == 1
    assert stable == (len({r["success"] for r in runs}) == 1), data["summary"]


def test_bad_seeds_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        rigid_motion.main(["--seeds", "0"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--seeds" in err, err
