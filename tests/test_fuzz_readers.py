"""The readers against random hostile documents (a small run; `python -m
experiments.fuzz_readers` runs 10,000 per reader): every mutated scenario, configuration and
plan is accepted or refused with the reader's own one-line error, never another exception."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments.fuzz_readers import READERS, mutate, run_reader


@pytest.mark.parametrize("name", sorted(READERS))
def test_mutated_documents_get_the_readers_own_error(name: str) -> None:
    base, read, errors = READERS[name]()
    rng = np.random.default_rng(1)
    documents = [mutate(base, rng, edits=int(rng.integers(1, 6))) for _ in range(150)]
    failures = run_reader(read, documents, errors)
    assert not failures, f"{name}: {len(failures)} of 150 documents escaped: {failures[:3]}"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(value=st.recursive(st.none() | st.booleans() | st.integers() | st.floats() |
                          st.text(max_size=40),
                          lambda inner: st.lists(inner, max_size=4) |
                          st.dictionaries(st.text(max_size=8), inner, max_size=4),
                          max_leaves=12),
       field=st.sampled_from(["gravity", "walls", "anchors", "start", "goal", "robot", "name"]))
def test_any_value_in_any_scenario_field(value, field: str) -> None:
    """Hypothesis's own values (subnormals, huge integers, unicode, nesting) in each field."""
    base, read, errors = READERS["scenario"]()
    doc = dict(base)
    doc[field] = value
    assert not run_reader(read, [doc], errors)
