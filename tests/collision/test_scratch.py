"""Placing per-call tables in lent memory (pscc.collision.scratch)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

from pscc.collision.scratch import ALIGNMENT, Lender, TableSpec, check_lender, place_tables, scratch_lenders
from pscc.errors import InputError

DTYPES = [wp.int32, wp.int64, wp.vec2i, wp.vec3, wp.float32]


def _span(array: wp.array) -> tuple[int, int]:
    return array.ptr, array.ptr + array.shape[0] * wp.types.type_size_in_bytes(array.dtype)


@settings(max_examples=60, deadline=None)
@given(counts=st.lists(st.integers(1, 300), min_size=1, max_size=8),
       kinds=st.lists(st.integers(0, len(DTYPES) - 1), min_size=8, max_size=8),
       outputs=st.lists(st.booleans(), min_size=8, max_size=8),
       lender_bytes=st.lists(st.integers(0, 4000), min_size=0, max_size=3),
       holds=st.lists(st.booleans(), min_size=3, max_size=3))
def test_tables_lie_inside_their_lenders_without_overlap_and_outputs_only_where_allowed(
        counts, kinds, outputs, lender_bytes, holds) -> None:
    tables = [TableSpec(f"t{k}", c, DTYPES[kinds[k]], outputs[k]) for k, c in enumerate(counts)]
    lenders = [Lender(wp.zeros(max(1, b // 4), dtype=wp.float32, device="cpu"), holds[k])
               for k, b in enumerate(lender_bytes)]
    placed, lent = place_tables(tables, lenders, wp.get_device("cpu"))
    assert set(placed) == {t.name for t in tables}
    spans = []
    for table in tables:
        array = placed[table.name]
        assert array.shape == (table.count,) and array.dtype == table.dtype
        start, end = _span(array)
        owner = [lender for lender in lenders if _span(lender.buffer)[0] <= start and end <= _span(lender.buffer)[1]]
        assert bool(owner) == (table.name in lent)
        if owner:
            assert start % ALIGNMENT == 0
            assert owner[0].holds_outputs or not table.output
            spans.append((start, end))
    spans.sort()
    assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:], strict=False))


def test_first_fit_decreasing_places_outputs_first_then_the_largest_tables() -> None:
    big = wp.zeros(100, dtype=wp.int32, device="cpu")  # 400 bytes, not for outputs
    small = wp.zeros(40, dtype=wp.int32, device="cpu")  # 160 bytes
    tables = [TableSpec("a", 10, wp.int32), TableSpec("b", 90, wp.int32), TableSpec("c", 40, wp.int32),
              TableSpec("out", 20, wp.int32, output=True)]
    placed, lent = place_tables(tables, [Lender(big, holds_outputs=False), Lender(small)], wp.get_device("cpu"))
    assert placed["out"].ptr == small.ptr  # 80 bytes: the output first, where outputs may go
    assert placed["b"].ptr == big.ptr  # 368 bytes: then the largest
    assert "c" not in lent  # 160 bytes: no room left anywhere, a buffer of its own
    assert placed["a"].ptr == small.ptr + 80  # 40 bytes: 32 left in the first lender, 80 in the second
    placed["c"].fill_(7)
    assert np.all(big.numpy() == 0) and np.all(small.numpy() == 0)


def test_a_lender_on_another_device_or_not_contiguous_is_refused() -> None:
    with pytest.raises(InputError, match="scratch"):
        check_lender(wp.zeros((4, 4), dtype=wp.float32, device="cpu")[:, 1], wp.get_device("cpu"), "scratch")
    with pytest.raises(InputError, match="scratch"):
        check_lender(np.zeros(4), wp.get_device("cpu"), "scratch")
    with pytest.raises(InputError, match="scratch: got list, not a function"):
        scratch_lenders([wp.zeros(4, device="cpu")], wp.get_device("cpu"))
    with pytest.raises(InputError, match=r"scratch\[1\]: is not a contiguous"):
        scratch_lenders(lambda: [wp.zeros(4, device="cpu"), np.zeros(4)], wp.get_device("cpu"))
