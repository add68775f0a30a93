"""benchmarks/tools/host_reads.DispatchCounter: the views and the bytes the other operations move, counted by hand."""

from __future__ import annotations

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.tools.host_reads import DispatchCounter

DTYPES = (torch.float64, torch.float32, torch.int64, torch.bool)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 5), st.integers(1, 7), st.sampled_from(DTYPES))
def test_an_elementwise_operation_moves_its_inputs_and_its_result(rows: int, columns: int, dtype: torch.dtype) -> None:
    a, b = torch.zeros(rows, columns, dtype=dtype), torch.zeros(rows, columns, dtype=dtype)
    counter = DispatchCounter()
    with counter:
        torch.maximum(a, b)  # out of place: two read, one written
        a.copy_(b)  # in place: b read, a read and written as the result
    size = rows * columns * a.element_size()
    assert counter.bytes_moved == 3 * size + 3 * size
    assert (counter.views, counter.kernels, counter.total) == (0, 2, 2)


def test_views_move_nothing_and_launch_no_kernel() -> None:
    a = torch.zeros(4, 6, dtype=torch.float64)
    counter = DispatchCounter()
    with counter:
        a[:, 1:3].t().reshape(2, 4).unsqueeze(0)
        a.unbind(0)
    assert counter.views == counter.total == 5 and counter.kernels == 0 and counter.bytes_moved == 0


def test_a_gather_reads_from_its_source_only_what_it_returns() -> None:
    grid = torch.zeros(1000, dtype=torch.float64)  # 8,000 bytes, of which 3 elements are gathered
    index = torch.tensor([0, 10, 999])
    counter = DispatchCounter()
    with counter:
        grid[index]
        torch.index_select(grid, 0, index)
    per_gather = 3 * 8 + 3 * 8 + 3 * 8  # indices, the gathered elements read, the result written
    assert counter.bytes_moved == 2 * per_gather and dict(counter.ops) == {"index": 1, "index_select": 1}


def test_by_source_attributes_the_bytes_to_the_lines_that_moved_them() -> None:
    from margin_rl.arrays import take_last

    values, index = torch.zeros(5, 4, dtype=torch.float64), torch.tensor([3, 0])
    counter = DispatchCounter(by_source=True)
    with counter:
        take_last(values, index)  # a helper of margin_rl/arrays.py: attributed to its caller, outside the package
    assert counter.source_bytes == {"elsewhere": 2 * 8 + 2 * 5 * 2 * 8}
