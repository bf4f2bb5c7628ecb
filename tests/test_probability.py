"""`planning.probability.path_probability` against values computed by hand.

p_path = prod_holdings min_t P_i(t) * (1 - attach_failure)^regrasps, where a holding is one boom
on one anchor from attach to detach, free booms (None) take no part, and the initial stance is
not a regrasp.
"""

from __future__ import annotations

import math

import pytest

from planning.probability import Configuration, PathProbability, path_probability

REL = 1e-12


def config(stance, p_grasp, p_success=None) -> Configuration:
    """A configuration; p_success defaults to the product of the attached booms' P."""
    if p_success is None:
        p_success = math.prod(p for a, p in zip(stance, p_grasp, strict=True) if a is not None)
    return Configuration(tuple(stance), tuple(p_grasp), p_success)


def test_empty_sequence_is_certain() -> None:
    result = path_probability([], attach_failure=0.1)
    assert isinstance(result, PathProbability)
    assert result.p_path == 1.0, f"no configuration, no risk: p_path {result.p_path}"
    assert result.p_min == 1.0
    assert result.regrasps == 0
    assert result.holdings == []


def test_single_configuration_is_the_product_of_its_grasps() -> None:
    c = config(("a", "b", "c", "d"), (0.9, 0.8, 1.0, 0.95))
    result = path_probability([c], attach_failure=0.25)
    expected = 0.9 * 0.8 * 1.0 * 0.95
    assert result.p_path == pytest.approx(expected, rel=REL), (
        "the initial stance must not pay the attach factor (1 - attach_failure)")
    assert result.regrasps == 0, "the initial stance does not count as regrasps"
    assert result.p_min == pytest.approx(expected, rel=REL)


def test_a_holding_survives_its_worst_instant() -> None:
    stance = ("a", "b", "c", "d")
    configs = [config(stance, (0.9, 0.8, 1.0, 0.95)),
               config(stance, (0.7, 0.85, 0.99, 0.96)),
               config(stance, (0.95, 0.9, 0.98, 0.5))]
    result = path_probability(configs, attach_failure=0.3)
    # min over time per boom: a 0.7, b 0.8, c 0.98, d 0.5 (not the product over time)
    assert result.p_path == pytest.approx(0.7 * 0.8 * 0.98 * 0.5, rel=REL), (
        f"p_path {result.p_path}: each holding counts once, at its minimum over configurations")
    assert result.regrasps == 0
    assert sorted(result.holdings) == [(0, "a", 0.7), (1, "b", 0.8), (2, "c", 0.98),
                                       (3, "d", 0.5)]


def test_p_min_is_the_smallest_configuration_probability() -> None:
    stance = ("a", "b", "c", "d")
    configs = [config(stance, (1.0,) * 4, 0.99),
               config(stance, (1.0,) * 4, 0.42),
               config(stance, (1.0,) * 4, 0.97)]
    result = path_probability(configs, attach_failure=0.0)
    assert result.p_min == pytest.approx(0.42, rel=REL), f"p_min {result.p_min}, expected 0.42"
    assert result.p_path == pytest.approx(1.0, rel=REL), (
        "p_path comes from p_grasp, not from p_success")


def test_a_regrasp_pays_the_attach_factor_and_splits_the_holdings() -> None:
    af = 0.1
    configs = [config(("a", "b", "c", "d"), (0.9, 0.9, 0.9, 0.9)),     # body
               config(("a", None, "c", "d"), (0.8, None, 0.95, 0.9)),  # reach: boom 1 free
               config(("a", "e", "c", "d"), (0.85, 0.6, 0.9, 0.99))]   # body on e
    result = path_probability(configs, attach_failure=af)
    # holdings: 1@b 0.9 (ends at the reach), then 0@a 0.8, 1@e 0.6, 2@c 0.9, 3@d 0.9
    expected = (1 - af) * 0.9 * 0.8 * 0.6 * 0.9 * 0.9
    assert result.regrasps == 1, f"{result.regrasps} regrasps, expected 1"
    assert result.p_path == pytest.approx(expected, rel=REL), (
        f"p_path {result.p_path}, hand value {expected}")
    assert result.holdings[0] == (1, "b", 0.9), (
        f"the first holding to end is boom 1 on b: {result.holdings}")
    assert sorted(result.holdings) == [(0, "a", 0.8), (1, "b", 0.9), (1, "e", 0.6),
                                       (2, "c", 0.9), (3, "d", 0.9)]


def test_returning_to_the_same_anchor_is_a_new_holding() -> None:
    """Leaving an anchor and grasping it again draws a new grasp: its minimum starts afresh."""
    af = 0.05
    configs = [config(("a", "b", "c", "d"), (1.0, 0.5, 1.0, 1.0)),
               config(("a", None, "c", "d"), (1.0, None, 1.0, 1.0)),
               config(("a", "b", "c", "d"), (1.0, 0.7, 1.0, 1.0))]
    result = path_probability(configs, attach_failure=af)
    assert result.regrasps == 1
    assert sorted(h for h in result.holdings if h[0] == 1) == [(1, "b", 0.5), (1, "b", 0.7)], (
        f"boom 1 must hold b twice, with separate minima: {result.holdings}")
    assert result.p_path == pytest.approx((1 - af) * 0.5 * 0.7, rel=REL)


def test_moving_straight_to_another_anchor_is_a_regrasp() -> None:
    af = 0.2
    configs = [config(("a", "b", "c", "d"), (0.9, 1.0, 1.0, 1.0)),
               config(("e", "b", "c", "d"), (0.8, 1.0, 1.0, 1.0))]
    result = path_probability(configs, attach_failure=af)
    assert result.regrasps == 1
    assert result.p_path == pytest.approx((1 - af) * 0.9 * 0.8, rel=REL)


def test_free_booms_do_not_count() -> None:
    # Boom 1 is free throughout; a number given for a free boom must be ignored too.
    configs = [config(("a", None, "c", "d"), (0.9, None, 0.8, 0.7)),
               Configuration(("a", None, "c", "d"), (0.95, 0.01, 0.85, 0.75), 0.9 * 0.8 * 0.7)]
    result = path_probability(configs, attach_failure=0.5)
    assert result.regrasps == 0, "a boom that stays free is never a regrasp"
    assert [h[0] for h in result.holdings] == [0, 2, 3], (
        f"only attached booms hold: {result.holdings}")
    assert result.p_path == pytest.approx(0.9 * 0.8 * 0.7, rel=REL), (
        f"p_path {result.p_path}: the free boom's 0.01 must not count")


def test_initial_three_stance_then_attaching_is_one_regrasp() -> None:
    """The first configuration's grasps are given; a later attach is a regrasp."""
    af = 0.1
    configs = [config(("a", None, "c", "d"), (1.0, None, 1.0, 1.0)),
               config(("a", "b", "c", "d"), (1.0, 0.9, 1.0, 1.0))]
    result = path_probability(configs, attach_failure=af)
    assert result.regrasps == 1
    assert result.p_path == pytest.approx((1 - af) * 0.9, rel=REL)


def test_two_regrasps_pay_the_attach_factor_twice() -> None:
    af = 0.01
    configs = [config(("a", "b", "c", "d"), (1.0,) * 4),
               config(("a", None, "c", "d"), (1.0, None, 1.0, 1.0)),
               config(("a", "e", "c", "d"), (1.0,) * 4),
               config(("a", "e", None, "d"), (1.0, 1.0, None, 1.0)),
               config(("a", "e", "f", "d"), (1.0,) * 4)]
    result = path_probability(iter(configs), attach_failure=af)  # any iterable, e.g. a generator
    assert result.regrasps == 2
    assert result.p_path == pytest.approx((1 - af) ** 2, rel=REL)
    assert len(result.holdings) == 6, f"4 initial + 2 new holdings: {result.holdings}"


def test_no_attach_failure_means_no_regrasp_cost() -> None:
    configs = [config(("a", "b", "c", "d"), (0.9,) * 4),
               config(("a", None, "c", "d"), (0.9, None, 0.9, 0.9)),
               config(("a", "e", "c", "d"), (0.9,) * 4)]
    result = path_probability(configs, attach_failure=0.0)
    assert result.regrasps == 1
    assert result.p_path == pytest.approx(0.9 ** 5, rel=REL)


def test_p_grasps_is_p_path_without_the_attach_term() -> None:
    """Two regrasps with attach failure 0.1: p_grasps keeps only the holdings' minima."""
    af = 0.1
    configs = [config(("a", "b", "c", "d"), (0.9, 1.0, 1.0, 1.0)),
               config(("e", "b", "c", "d"), (0.8, 1.0, 1.0, 1.0)),
               config(("e", "f", "c", "d"), (0.8, 0.7, 1.0, 1.0))]
    result = path_probability(configs, attach_failure=af)
    assert result.regrasps == 2
    assert result.p_grasps == pytest.approx(0.9 * 0.8 * 0.7, rel=REL), (
        f"p_grasps {result.p_grasps}: the product of the four holdings' minima")
    assert result.p_path == pytest.approx(result.p_grasps * (1 - af) ** 2, rel=REL), (
        f"p_path {result.p_path} must be p_grasps {result.p_grasps} times 0.9^2")
