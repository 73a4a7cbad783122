"""The feature mode's compiled ring loops (``o3d_lsmesh/_feature_kernel.pyx``) against plain loops over rows."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh._feature_kernel import (
    filtered_normals,
    least_dot,
    patch_pairs,
    patch_saliency,
    plane_steps,
    ring_least,
    ring_spacing,
)


@st.composite
def patterns(draw):
    """``(indptr, indices)`` of an ``(m, m)`` CSR pattern (empty rows, repeated columns and any order
    allowed), int32 or int64, and a seed for its values."""
    m = draw(st.integers(1, 9))
    rows = draw(st.lists(st.lists(st.integers(0, m - 1), max_size=6), min_size=m, max_size=m))
    index = draw(st.sampled_from([np.int32, np.int64]))
    indptr = np.array([0, *np.cumsum([len(r) for r in rows])], dtype=index)
    indices = np.array([j for r in rows for j in r], dtype=index)
    return indptr, indices, draw(st.integers(0, 2**16))


def _stored(indptr, indices):
    """``(i, j)`` of each stored entry, in stored order."""
    return [(i, int(indices[k])) for i in range(len(indptr) - 1) for k in range(indptr[i], indptr[i + 1])]


def _distance2(c, i, j):
    s = 0.0
    for a in range(3):
        s = s + (c[i, a] - c[j, a]) * (c[i, a] - c[j, a])
    return s


def _dot(a, i, b, j):
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


def _unit_rows(rng, m):
    v = rng.standard_normal((m, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@settings(max_examples=80, deadline=None)
@given(patterns())
def test_ring_spacing_is_the_sum_of_the_entries_distances(pattern):
    indptr, indices, seed = pattern
    centroid = np.random.default_rng(seed).standard_normal((len(indptr) - 1, 3)) + 100.0
    want = math.fsum(math.sqrt(_distance2(centroid, i, j)) for i, j in _stored(indptr, indices))
    assert ring_spacing(indptr, indices, centroid) == pytest.approx(want, rel=1e-13, abs=1e-300)


@settings(max_examples=80, deadline=None)
@given(patterns(), st.floats(0.1, 2.0), st.floats(0.01, 3.0))
def test_filtered_normals_are_a_loop_over_each_rows_entries(pattern, sigma_r, spacing):
    indptr, indices, seed = pattern
    m = len(indptr) - 1
    rng = np.random.default_rng(seed)
    centroid, guide, normals, area = (
        rng.standard_normal((m, 3)),
        _unit_rows(rng, m),
        _unit_rows(rng, m),
        rng.random(m),
    )
    range_divisor, space_divisor = sigma_r**2, 2.0 * spacing**2
    want = np.zeros((m, 3))
    for i, j in _stored(indptr, indices):
        w = (_dot(guide, i, guide, j) - 1.0) / range_divisor
        w = math.exp(w - _distance2(centroid, i, j) / space_divisor) * area[j]
        want[i] += w * normals[j]
    out = np.full((m, 3), np.nan)
    filtered_normals(indptr, indices, centroid, guide, area, normals, range_divisor, space_divisor, out)
    np.testing.assert_allclose(out, want, rtol=1e-13, atol=1e-300)


@settings(max_examples=80, deadline=None)
@given(patterns())
def test_least_dot_is_each_rows_least_product_and_zero_on_an_empty_row(pattern):
    indptr, indices, seed = pattern
    m = len(indptr) - 1
    rng = np.random.default_rng(seed)
    a, b = rng.standard_normal((2, m, 3))
    want = [0.0] * m
    for i in range(m):
        row = [_dot(a, i, b, int(j)) for j in indices[indptr[i] : indptr[i + 1]]]
        want[i] = min(row) if row else 0.0
    assert least_dot(indptr, indices, a, b).tolist() == want


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_an_empty_row_gives_zero_sums_and_a_zero_least(index):
    indptr, indices = np.array([0, 2, 2, 3], dtype=index), np.array([0, 2, 1], dtype=index)
    centroid = np.array([[0.0, 0, 0], [0, 0, 0], [0, 3, 4]])
    normals = np.array([[0.0, 0, 1], [0, 1, 0], [1, 0, 0]])
    out = np.full((3, 3), np.nan)
    filtered_normals(indptr, indices, centroid, normals, np.ones(3), normals, 1.0, 1.0, out)
    assert out[1].tolist() == [0.0, 0.0, 0.0] and out[0].tolist() == [math.exp(-1.0 - 25.0), 0.0, 1.0]
    assert least_dot(indptr, indices, normals, normals).tolist() == [0.0, 0.0, 0.0]
    assert least_dot(indptr, indices, normals, -normals).tolist() == [-1.0, 0.0, 0.0]
    assert ring_spacing(indptr, indices, centroid) == 5.0 + 5.0
    empty = np.zeros(1, dtype=index), np.zeros(0, dtype=index)
    assert ring_spacing(*empty, np.zeros((0, 3))) == 0.0 and len(least_dot(*empty, *np.zeros((2, 0, 3)))) == 0


def test_the_loops_on_threads_give_the_results_of_one_thread():
    from threadpoolctl import threadpool_limits

    # above the rows where the loops go parallel: each row summed in its stored order on either count
    rng = np.random.default_rng(39)
    m = 100_000
    indptr = np.r_[0, np.cumsum(rng.integers(0, 15, m))].astype(np.int64)
    indices = rng.integers(0, m, indptr[-1])
    centroid, guide, normals, area = (
        rng.standard_normal((m, 3)),
        _unit_rows(rng, m),
        _unit_rows(rng, m),
        rng.random(m),
    )
    results = []
    for limit in (1, 2):
        with threadpool_limits(limits=limit, user_api="openmp"):
            out = np.empty((m, 3))
            filtered_normals(indptr, indices, centroid, guide, area, normals, 0.12, 0.5, out)
            results.append(
                (ring_spacing(indptr, indices, centroid), least_dot(indptr, indices, guide, normals), out)
            )
    assert results[0][0] == results[1][0]
    assert np.array_equal(results[0][1], results[1][1]) and np.array_equal(results[0][2], results[1][2])


@pytest.mark.parametrize(
    "kernel, position, value, match",
    [
        (ring_spacing, 0, np.zeros(0, np.int64), r"indptr must have at least 1 entry, got 0"),
        (
            ring_spacing,
            0,
            np.array([0, 1, 2, 4]),
            r"indptr must run from 0 to the pattern's 3 entries, got 0 to 4",
        ),
        (
            ring_spacing,
            0,
            np.array([1, 1, 2, 3]),
            r"indptr must run from 0 to the pattern's 3 entries, got 1 to 3",
        ),
        (ring_spacing, 2, np.zeros((2, 3)), r"centroid must have shape \(3, 3\), got \(2, 3\)"),
        (ring_spacing, 2, np.zeros((3, 2)), r"centroid must have shape \(3, 3\), got \(3, 2\)"),
        (filtered_normals, 0, np.array([0, 1, 2, 4]), r"indptr must run from 0 to the pattern's 3 entries"),
        (filtered_normals, 2, np.zeros((4, 3)), r"centroid must have shape \(3, 3\), got \(4, 3\)"),
        (filtered_normals, 3, np.zeros((3, 4)), r"guide must have shape \(3, 3\), got \(3, 4\)"),
        (filtered_normals, 4, np.ones(2), r"area must have shape \(3,\), got \(2,\)"),
        (filtered_normals, 5, np.zeros((2, 3)), r"normals must have shape \(3, 3\), got \(2, 3\)"),
        (filtered_normals, 8, np.zeros((3, 1)), r"out must have shape \(3, 3\), got \(3, 1\)"),
        (least_dot, 0, np.zeros(0, np.int64), r"indptr must have at least 1 entry, got 0"),
        (least_dot, 2, np.zeros((2, 3)), r"a must have shape \(3, 3\), got \(2, 3\)"),
        (least_dot, 3, np.zeros((3, 2)), r"b must have shape \(3, 3\), got \(3, 2\)"),
    ],
)
def test_each_kernel_names_the_argument_of_the_wrong_shape(kernel, position, value, match):
    indptr, indices = np.arange(4, dtype=np.int64), np.arange(3, dtype=np.int64)
    v = np.zeros((3, 3))
    args = {
        ring_spacing: [indptr, indices, v],
        filtered_normals: [indptr, indices, v, v, np.ones(3), v, 1.0, 1.0, np.zeros((3, 3))],
        least_dot: [indptr, indices, v, v],
    }[kernel]
    args[position] = value.astype(np.int64) if position == 0 else value
    with pytest.raises(ValueError, match=match):
        kernel(*args)


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_the_moved_loops_refuse_patterns_of_another_size(index):
    with pytest.raises(ValueError, match="indptr ends at 3, the pattern has 2 entries"):
        ring_least(np.array([0, 1, 3], dtype=index), np.zeros(2, dtype=index), np.zeros(2))
    corners, indptr, faces = (
        np.arange(3, dtype=index),
        np.array([0, 1, 2, 3], dtype=index),
        np.zeros(3, dtype=index),
    )
    with pytest.raises(ValueError, match="corners must have 6 entries and indptr 4, ending at len"):
        plane_steps(corners, indptr, faces, np.zeros((2, 3)), np.zeros((3, 3)), 1)
    with pytest.raises(ValueError, match="normals and x must have 3 columns, got 3 and 2"):
        plane_steps(corners, indptr, faces, np.zeros((1, 3)), np.zeros((3, 2)), 1)


@settings(max_examples=80, deadline=None)
@given(patterns())
def test_ring_least_is_the_first_column_of_least_value(pattern):
    indptr, indices, seed = pattern
    values = np.random.default_rng(seed).integers(0, 4, len(indptr) - 1).astype(np.float64)  # ties
    want = []
    for i in range(len(indptr) - 1):
        row = [int(j) for j in indices[indptr[i] : indptr[i + 1]]]
        want.append(min(row, key=lambda j: values[j]) if row else -1)  # min keeps the first of ties
    assert ring_least(indptr, indices, values).tolist() == want


@st.composite
def rings_and_pairs(draw):
    """A symmetric ring pattern with sorted rows (each face in its own ring) and pairs of faces, as the
    feature mode's face adjacency has them, int32 or int64."""
    m = draw(st.integers(1, 8))
    linked = draw(st.sets(st.tuples(st.integers(0, m - 1), st.integers(0, m - 1)), max_size=12))
    ring = [{i} for i in range(m)]
    for a, b in linked:
        ring[a].add(b)
        ring[b].add(a)
    pairs = draw(st.lists(st.tuples(st.integers(0, m - 1), st.integers(0, m - 1)), max_size=10))
    index = draw(st.sampled_from([np.int32, np.int64]))
    indptr = np.array([0, *np.cumsum([len(r) for r in ring])], dtype=index)
    indices = np.array([j for r in ring for j in sorted(r)], dtype=index)
    return indptr, indices, np.array(pairs, dtype=np.int64).reshape(-1, 2), draw(st.integers(0, 2**16))


def _first(pairs, m, index):
    """Each face's pairs as their first face, CSR, the pairs increasing."""
    order = sorted(range(len(pairs)), key=lambda q: (pairs[q, 0], q))
    indptr = np.array([0, *np.cumsum(np.bincount(pairs[:, 0], minlength=m))], dtype=index)
    return indptr, np.array(order, dtype=index)


@settings(max_examples=100, deadline=None)
@given(rings_and_pairs())
def test_patch_pairs_are_each_patchs_pairs_once_in_ring_order(case):
    indptr, indices, pairs, seed = case
    m = len(indptr) - 1
    first_indptr, first_pairs = _first(pairs, m, indptr.dtype)
    got_indptr, got = patch_pairs(
        indptr, indices, first_indptr, first_pairs, np.ascontiguousarray(pairs[:, 1])
    )
    assert got_indptr.dtype == got.dtype == indptr.dtype
    for i in range(m):
        ring = indices[indptr[i] : indptr[i + 1]].tolist()
        want = [
            q
            for j in ring
            for q in first_pairs[first_indptr[j] : first_indptr[j + 1]].tolist()
            if pairs[q, 1] in ring
        ]
        assert got[got_indptr[i] : got_indptr[i + 1]].tolist() == want
    # the saliency over those pairs, summed in stored order
    jump = np.random.default_rng(seed).random(len(pairs))
    saliency = patch_saliency(got_indptr, got, jump)
    for i in range(m):
        inside = [jump[q] for q in got[got_indptr[i] : got_indptr[i + 1]]]
        total = 0.0
        for value in inside:
            total = total + value
        assert saliency[i] == max(inside, default=0.0) / (1e-9 + total)


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_patch_pairs_and_saliency_refuse_inconsistent_arrays(index):
    indptr, indices = np.array([0, 1, 2], dtype=index), np.array([0, 1], dtype=index)
    first_indptr, first_pairs = np.array([0, 1, 1], dtype=index), np.array([0], dtype=index)
    second = np.array([1], dtype=np.int64)
    with pytest.raises(ValueError, match="first_indptr must have 3 entries"):
        patch_pairs(indptr, indices, np.array([0, 1], dtype=index), first_pairs, second)
    with pytest.raises(ValueError, match="first_pairs must name pairs of second in 0..0, got 3"):
        patch_pairs(indptr, indices, first_indptr, np.array([3], dtype=index), second)
    with pytest.raises(ValueError, match="second must name faces in 0..1, got 2"):
        patch_pairs(indptr, indices, first_indptr, first_pairs, np.array([2], dtype=np.int64))
    got_indptr, got = patch_pairs(indptr, indices, first_indptr, first_pairs, second)
    assert got_indptr.tolist() == [0, 0, 0] and got.tolist() == []  # face 1 is in no ring of face 0
    with pytest.raises(ValueError, match="pairs must name entries of jump in 0..0, got 4"):
        patch_saliency(np.array([0, 1], dtype=index), np.array([4], dtype=index), np.array([0.5]))
    assert patch_saliency(got_indptr, got, np.array([0.5])).tolist() == [0.0, 0.0]
