"""margin_rl.arrays: which namespace a computation's inputs get, and the few-operation helpers the equations share."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.tools.host_reads import DispatchCounter
from margin_rl.arrays import (
    TorchRandom,
    constant,
    finite_mask,
    finite_or_zero,
    generator_state,
    like,
    namespace,
    random_generator,
    rotate,
    set_generator_state,
    split_columns,
    take_last,
    to_numpy,
    uniform_columns,
    unstack,
    write_where,
)


def test_numpy_inputs_and_python_values_get_numpy_itself() -> None:
    """numpy itself (its own functions and numbers), also for numpy scalars and plain Python values."""
    assert namespace(np.zeros(3), 1.0, [1, 2], np.float64(2.0), True) is np
    assert namespace() is np


def test_torch_tensors_get_the_torch_namespace_on_their_device() -> None:
    xp = namespace(torch.zeros(3, dtype=torch.float64), 0.5)
    assert xp.__name__ == "array_api_compat.torch"
    assert xp.concat([torch.ones(2), torch.zeros(1)], axis=0).tolist() == [1.0, 1.0, 0.0]


def test_mixed_kinds_are_refused() -> None:
    with pytest.raises(TypeError, match="Multiple namespaces"):
        namespace(np.zeros(2), torch.zeros(2))


def test_to_numpy_and_like_move_between_kinds_without_copying_numpy() -> None:
    host = np.arange(6.0).reshape(2, 3)
    assert to_numpy(host) is host  # numpy passes through
    tensor = like(host, torch.zeros(1))
    assert isinstance(tensor, torch.Tensor) and tensor.dtype == torch.float64
    np.testing.assert_array_equal(to_numpy(tensor), host)
    assert like(host, np.zeros(1)) is host
    read_only = np.arange(3.0)
    read_only.flags.writeable = False
    copied = like(read_only, torch.zeros(1))
    copied += 1  # a copy: the read-only array is untouched
    np.testing.assert_array_equal(read_only, [0.0, 1.0, 2.0])
    assert like(tensor, torch.zeros(1)) is tensor  # already of the kind: no copy


def test_random_generator_draws_on_the_reference_kind() -> None:
    assert isinstance(random_generator(3, np.zeros(1)), np.random.Generator)
    rng = random_generator(3, torch.zeros(1))
    assert isinstance(rng, TorchRandom)
    u = rng.uniform(-2.0, 3.0, size=(400, 3))
    assert u.dtype == torch.float64 and u.shape == (400, 3) and float(u.min()) >= -2.0 and float(u.max()) < 3.0
    k = rng.integers(0, 5, size=400)
    assert k.dtype == torch.int64 and set(k.tolist()) == {0, 1, 2, 3, 4}
    e = rng.exponential(2.0, size=20000)
    assert float(e.min()) >= 0.0 and abs(float(e.mean()) - 2.0) < 0.1  # mean 2, standard error 0.014


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_torch_draws_are_reproducible_and_survive_pickling_and_checkpoints(seed: int) -> None:
    a, b = TorchRandom(seed, "cpu"), TorchRandom(seed, "cpu")
    assert torch.equal(a.uniform(0, 1, 5), b.uniform(0, 1, 5))
    copied = pickle.loads(pickle.dumps(a))
    assert torch.equal(a.exponential(1.0, 4), copied.exponential(1.0, 4))
    saved = generator_state(a)
    first = a.integers(0, 100, 8)
    set_generator_state(a, saved)
    assert torch.equal(a.integers(0, 100, 8), first)
    host = np.random.default_rng(seed)
    saved = generator_state(host)
    first_host = host.uniform(size=3)
    set_generator_state(host, saved)
    np.testing.assert_array_equal(host.uniform(size=3), first_host)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 6), st.integers(1, 5), st.booleans(), st.integers(0, 2**32 - 1))
def test_rotate_is_the_matrix_product_on_numpy_and_on_torch(n: int, k: int, inverse: bool, seed: int) -> None:
    """R v (R^T v) for one vector or k per matrix, against a Python loop; torch's batched product equals numpy's
    einsum to rounding, and numpy's answer is einsum's bit for bit."""
    rng = np.random.default_rng(seed)
    R, vectors = rng.normal(size=(n, 3, 3)), rng.normal(size=(n, k, 3))
    for v in (vectors, vectors[:, 0]):
        expected = np.array(
            [[(R[i].T if inverse else R[i]) @ w for w in np.atleast_2d(v[i])] for i in range(n)]
        ).reshape(v.shape)
        result = rotate(R, v, inverse)
        assert result.shape == v.shape
        np.testing.assert_allclose(result, expected, rtol=1e-12, atol=1e-12)
        subscripts = ("nji" if inverse else "nij") + (",nj->ni" if v.ndim == 2 else ",nkj->nki")
        assert result.tobytes() == np.einsum(subscripts, R, v).tobytes()
        on_torch = rotate(torch.as_tensor(R), torch.as_tensor(v), inverse)
        np.testing.assert_allclose(on_torch.numpy(), expected, rtol=1e-12, atol=1e-12)


def test_a_constant_is_made_once_per_device_and_is_numpy_itself_on_the_host() -> None:
    reference = torch.zeros(2, dtype=torch.float64)
    first, again = constant(np.array([1, 2, 3]), reference), constant(np.array([1, 2, 3]), reference)
    assert first is again and first.device == reference.device and first.dtype == torch.int64
    assert constant(np.array([1.0, 2.0, 3.0]), reference) is not first  # another dtype, another constant
    host = constant([0.5, 1.5], np.zeros(2))
    assert isinstance(host, np.ndarray) and host.tolist() == [0.5, 1.5]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=1, max_size=8))
def test_finite_mask_is_isfinite_on_numpy_and_torch(values: list[float]) -> None:
    for dtype in (np.float32, np.float64):
        host = np.array(values, dtype=dtype)
        np.testing.assert_array_equal(finite_mask(host), np.isfinite(host))
        device = torch.as_tensor(host)
        assert torch.equal(finite_mask(device), torch.isfinite(device))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=1, max_size=8))
def test_finite_or_zero_is_where_finite_else_zero_on_numpy_and_torch(values: list[float]) -> None:
    for dtype in (np.float32, np.float64):
        host = np.array(values, dtype=dtype)
        expected = np.where(np.isfinite(host), host, 0.0).astype(dtype)
        assert finite_or_zero(host).tobytes() == expected.tobytes()  # bit for bit, the sign of a zero included
        assert finite_or_zero(torch.as_tensor(host)).numpy().tobytes() == expected.tobytes()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(1, 4), min_size=1, max_size=5), st.integers(1, 3))
def test_split_columns_and_unstack_are_the_slices_as_views(widths: list[int], n: int) -> None:
    """The pieces are block[:, a:b] for consecutive ranges (views: a write shows in the block), one operation on
    torch; unstack gives the columns."""
    for block in (np.arange(n * sum(widths), dtype=np.float64).reshape(n, -1), torch.zeros(n, sum(widths))):
        if isinstance(block, torch.Tensor):
            block += torch.arange(n * sum(widths)).reshape(n, -1)
        pieces = split_columns(block, widths)
        starts = np.cumsum([0, *widths])
        for piece, start, stop in zip(pieces, starts[:-1], starts[1:], strict=True):
            assert to_numpy(piece).tolist() == to_numpy(block[:, start:stop]).tolist()
        pieces[-1][...] = -1  # a view of the block
        assert (to_numpy(block)[:, -widths[-1] :] == -1).all()
        columns = unstack(block)
        assert [to_numpy(c).tolist() for c in columns] == [to_numpy(block[:, k]).tolist() for k in range(sum(widths))]
        cube = block.reshape(n, 1, -1)
        assert [to_numpy(c).tolist() for c in unstack(cube, axis=-1)] == [
            to_numpy(cube[..., k]).tolist() for k in range(sum(widths))
        ]
    counter = DispatchCounter()
    with counter:
        split_columns(torch.zeros(n, sum(widths)), widths)
        unstack(torch.zeros(n, 3))
    assert dict(counter.ops) == {"zeros": 2, "split_with_sizes": 1, "unbind": 1}


def test_split_columns_refuses_widths_that_do_not_cover_the_block() -> None:
    with pytest.raises(ValueError, match=r"column widths \[2, 2\] sum to 4, but the block has 5 columns"):
        split_columns(np.zeros((2, 5)), [2, 2])


def test_take_last_is_numpys_take_and_one_torch_operation() -> None:
    values = np.arange(24.0).reshape(2, 3, 4)
    index = np.array([3, 0, 0, 2])
    expected = np.take(values, index, axis=-1)
    assert take_last(values, index).tobytes() == expected.tobytes() and expected.flags.c_contiguous
    values_t, index_t, counter = torch.as_tensor(values), torch.as_tensor(index), DispatchCounter()
    with counter:
        on_torch = take_last(values_t, index_t)
    assert on_torch.numpy().tolist() == expected.tolist() and dict(counter.ops) == {"index_select": 1}


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 3), st.integers(0, 2**32 - 1), st.booleans())
def test_write_where_writes_the_masked_rows_in_place(n: int, width: int, seed: int, scalar: bool) -> None:
    """The rows where the mask holds take the values, the others keep theirs, in place, on numpy and torch; a mask
    already shaped over the rows ((N, 1)) as well."""
    rng = np.random.default_rng(seed)
    mask, before = rng.random(n) < 0.5, rng.normal(size=(n, width))
    values = 7.5 if scalar else rng.normal(size=(n, width))
    expected = np.where(mask[:, None], values, before)
    for kind in (np.asarray, torch.as_tensor):
        for rows in (kind(mask), kind(mask)[:, None]):
            target = kind(before.copy())
            address = target.ctypes.data if isinstance(target, np.ndarray) else target.data_ptr()
            write_where(target, rows, values if scalar else kind(values))
            assert to_numpy(target).tolist() == expected.tolist()
            assert address == (target.ctypes.data if isinstance(target, np.ndarray) else target.data_ptr())


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 50), st.integers(0, 2**32 - 1), st.booleans())
def test_uniform_columns_keep_numpys_stream_and_draw_once_on_torch(n: int, seed: int, friction: bool) -> None:
    """numpy: the arrays one rng.uniform call after another would give, bit for bit (a reset's stream unchanged; a
    per-column block as one (n,) call per column, stacked); torch: one draw for all of them, each array within its
    bounds (per column for a block) and of its shape."""
    commands = ((-0.5, 0.0, -1.0), (1.5, 0.0, 1.0), 3)  # a column each, the middle one constant
    bounds = ((-1, 1, 12), (-1, 1, 6), *(((0.4, 1.2, None),) if friction else ()), (-0.5, 1.5, None), commands)
    expected_rng, rng = np.random.default_rng(seed), np.random.default_rng(seed)
    expected = [expected_rng.uniform(lo, hi, size=n if w is None else (n, w)) for lo, hi, w in bounds[:-1]]
    expected.append(
        np.stack([expected_rng.uniform(lo, hi, size=n) for lo, hi in zip(*commands[:2], strict=True)], axis=1)
    )
    drawn = uniform_columns(rng, n, bounds)
    assert [a.tobytes() for a in drawn] == [a.tobytes() for a in expected]
    assert rng.uniform() == expected_rng.uniform()  # the same count drawn
    torch_rng = TorchRandom(seed, "cpu")
    counter = DispatchCounter()
    with counter:
        on_torch = uniform_columns(torch_rng, n, bounds)
    assert counter.random_numbers == n * sum(1 if w is None else w for _, _, w in bounds)
    lows = [np.full(w or 1, lo) for lo, _, w in bounds[:-1]] + [np.array(commands[0])]
    highs = [np.full(w or 1, hi) for _, hi, w in bounds[:-1]] + [np.array(commands[1])]
    for array, (_, _, w), lo, hi in zip(on_torch, bounds, lows, highs, strict=True):
        assert tuple(array.shape) == ((n,) if w is None else (n, w)) and array.dtype == torch.float64
        values = array.numpy().reshape(n, -1)
        assert (values >= lo).all() and ((values < hi) | (lo == hi)).all()
    assert (on_torch[-1][:, 1] == 0.0).all()
    again = uniform_columns(TorchRandom(seed, "cpu"), n, bounds)
    assert all(torch.equal(a, b) for a, b in zip(on_torch, again, strict=True))


@pytest.mark.parametrize("bounds", [((0.0, 1.0), (1.0, 2.0), 3), ((0.0, 1.0), 2.0, 2), ((0.0, 1.0), (1.0, 2.0), None)])
def test_uniform_columns_refuse_per_column_bounds_of_another_width(bounds: tuple) -> None:
    """Per-column bounds whose lengths do not match each other and the width: a ValueError, on numpy and torch."""
    for rng in (np.random.default_rng(0), TorchRandom(0, "cpu")):
        with pytest.raises(ValueError, match="per-column bounds"):
            uniform_columns(rng, 4, (bounds,))
