"""The core's array helpers against NumPy's own forms."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh.core.arrays import in_sorted


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.integers(-20, 20), max_size=15),
    st.lists(st.integers(-25, 25), max_size=30),
)
def test_in_sorted_is_isin(pool, values):
    sorted_values = np.unique(np.array(pool, dtype=np.int64))
    values = (
        np.array(values, dtype=np.int64).reshape(-1, 1) if len(values) % 2 else np.array(values, np.int64)
    )
    np.testing.assert_array_equal(in_sorted(sorted_values, values), np.isin(values, sorted_values))


def test_mean_edge_length_is_a_plain_loops():
    from o3d_lsmesh.core.arrays import mean_edge_length

    rng = np.random.default_rng(4)
    vertices, triangles = rng.normal(size=(30, 3)), rng.integers(0, 30, size=(40, 3))
    lengths = [np.linalg.norm(vertices[t[(c + 1) % 3]] - vertices[t[c]]) for t in triangles for c in range(3)]
    assert mean_edge_length(vertices, triangles) == pytest.approx(sum(lengths) / len(lengths), rel=1e-12)
