"""Tests of sampling, labelling and the k-d-tree failure margin."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from margin_rl.slip.margin import (
    BOX_HIGH,
    BOX_LOW,
    MARGIN_WEIGHTS,
    FailureMargin,
    brute_force_oriented_distance,
    label_samples,
    sample_box,
    weighted_norm,
)


def test_sample_box_is_uniform_inside_bounds() -> None:
    z = sample_box(20_000, np.random.default_rng(0))
    assert z.shape == (20_000, 4)
    assert np.all(z >= BOX_LOW) and np.all(z <= BOX_HIGH)
    # Means of a uniform box are its centre (4 sigma of the sample mean ~ 0.02 of the range).
    np.testing.assert_allclose((z.mean(axis=0) - BOX_LOW) / (BOX_HIGH - BOX_LOW), 0.5, atol=0.02)


def test_weighted_norm_uses_diagonal_weights() -> None:
    d = np.array([[0.4, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]])
    expected = [1.0, 1.0, np.sqrt(MARGIN_WEIGHTS.sum())]
    np.testing.assert_allclose(weighted_norm(d), expected)
    with pytest.raises(ValueError, match="weights"):
        weighted_norm(d, [1.0, -1.0, 1.0, 1.0])


def test_label_samples_has_both_classes_in_box() -> None:
    z = sample_box(2000, np.random.default_rng(1))
    res = label_samples(z)
    frac = res.valid.mean()
    assert 0.05 < frac < 0.6
    assert np.all(np.isfinite(res.next_apex[res.valid]))
    assert np.all(np.isnan(res.next_apex[~res.valid]))


def _random_labelled(seed: int, n_tree: int, n_query: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    tree_pts = sample_box(n_tree, rng)
    # A curved synthetic boundary keeps the test independent of the simulator.
    tree_lab = (tree_pts[:, 0] - 1.0) ** 2 + 0.1 * tree_pts[:, 1] ** 2 < 0.02 + 0.05 * tree_pts[:, 2] ** 2
    queries = sample_box(n_query, rng)
    q_lab = rng.random(n_query) < 0.5
    return tree_pts, tree_lab, queries, q_lab


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), n_tree=st.integers(2, 60), n_query=st.integers(1, 30))
def test_kd_tree_margin_equals_brute_force(seed: int, n_tree: int, n_query: int) -> None:
    tree_pts, tree_lab, q, q_lab = _random_labelled(seed, n_tree, n_query)
    if tree_lab.all() or not tree_lab.any():
        tree_lab[0] = not tree_lab[0]
    fm = FailureMargin.from_samples(tree_pts, tree_lab)
    got = fm.oriented_distance(q, q_lab)
    want = brute_force_oriented_distance(q, q_lab, tree_pts[tree_lab], tree_pts[~tree_lab])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert np.all((got > 0) == q_lab)


def test_tree_samples_get_the_same_margin_as_fresh_queries() -> None:
    tree_pts, tree_lab, _, _ = _random_labelled(5, 300, 1)
    fm = FailureMargin.from_samples(tree_pts, tree_lab)
    got = fm.oriented_distance(tree_pts, tree_lab)
    # Brute force treats each point as a fresh query against the *other* points only.
    want = np.array(
        [
            brute_force_oriented_distance(
                tree_pts[i : i + 1],
                tree_lab[i : i + 1],
                np.delete(tree_pts, i, 0)[np.delete(tree_lab, i)],
                np.delete(tree_pts, i, 0)[~np.delete(tree_lab, i)],
            )[0]
            for i in range(len(tree_pts))
        ]
    )
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_unlabelled_margin_is_zero_between_two_points() -> None:
    pts = np.array([[1.0, 0.0, 0.0, 0.0], [1.2, 0.0, 0.0, 0.0]])
    fm = FailureMargin.from_samples(pts, np.array([True, False]))
    mid = np.array([[1.1, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    b = fm.oriented_distance_unlabelled(mid)
    assert b[0] == pytest.approx(0.0, abs=1e-12)
    assert b[1] == pytest.approx(0.2 * 2.5)  # sqrt(6.25) * 0.2


def test_failure_margin_rejects_bad_input() -> None:
    pts = sample_box(5, np.random.default_rng(0))
    with pytest.raises(ValueError, match="both"):
        FailureMargin.from_samples(pts, np.ones(5, dtype=bool))
    with pytest.raises(ValueError, match="valid"):
        FailureMargin.from_samples(pts, np.ones(4, dtype=bool))
    with pytest.raises(ValueError, match="z"):
        FailureMargin.from_samples(pts[:, :3], np.ones(5, dtype=bool))
