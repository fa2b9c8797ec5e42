"""The driver's row copies (``distributed.row_kernels``) against numpy's fancy indexing (hypothesis), and their
bad-input table."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.distributed.row_kernels import gather_rows, scatter_rows


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_slots=st.integers(1, 40),
    width=st.integers(1, 9),
    readonly=st.booleans(),
    strided=st.booleans(),
)
def test_row_copies_equal_fancy_indexing(seed: int, n_slots: int, width: int, readonly: bool, strided: bool) -> None:
    rng = np.random.default_rng(seed)
    k = int(rng.integers(0, n_slots + 1))
    slots = rng.permutation(n_slots)[:k].astype(np.int64)
    rows = rng.normal(size=(k, width)).astype(np.float32)
    slots.flags.writeable = rows.flags.writeable = not readonly
    out = rng.normal(size=(n_slots, width)).astype(np.float32)
    want = out.copy()
    want[slots] = rows
    scatter_rows(out, slots, rows)
    np.testing.assert_array_equal(out, want)

    wide = rng.normal(size=(n_slots, width + 3))
    src = wide[:, 1 : 1 + width] if strided else np.ascontiguousarray(wide[:, 1 : 1 + width])
    got = np.full((k, width), np.nan)
    gather_rows(src, slots, got)
    np.testing.assert_array_equal(got, src[slots])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda: scatter_rows(np.zeros((3, 2), np.float32), np.array([0, 3]), np.zeros((2, 2), np.float32)),
            r"\[0, 3\)",
        ),
        (lambda: scatter_rows(np.zeros((3, 2), np.float32), np.array([-1]), np.zeros((1, 2), np.float32)), r"\[0, 3\)"),
        (lambda: scatter_rows(np.zeros((3, 2), np.float32), np.array([0]), np.zeros((2, 2), np.float32)), r"\(2,\)"),
        (lambda: gather_rows(np.zeros((3, 2)), np.array([5]), np.zeros((1, 2))), r"\[0, 3\)"),
        (lambda: gather_rows(np.zeros((3, 2)), np.array([0, 1]), np.zeros((1, 2))), r"\(1,\)"),
    ],
)
def test_bad_slots_name_the_function_and_the_bounds(call: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()  # type: ignore[operator]


def test_other_dtypes_fall_back_to_numpy() -> None:
    out = np.zeros((3, 2))
    scatter_rows(out, np.array([2], dtype=np.int32), np.ones((1, 2), np.float32))
    np.testing.assert_array_equal(out[2], [1, 1])
    got = np.zeros((1, 2), np.float32)
    gather_rows(np.arange(6.0).reshape(3, 2), np.array([1]), got)
    np.testing.assert_array_equal(got, [[2, 3]])


@pytest.mark.parametrize("n", [10, 8192, 20001])
def test_a_scatter_split_over_two_threads_writes_what_one_thread_does(n: int) -> None:
    rng = np.random.default_rng(n)
    slots = rng.permutation(n + 50)[:n].astype(np.int64)
    rows = rng.normal(size=(n, 7)).astype(np.float32)
    one = rng.normal(size=(n + 50, 7)).astype(np.float32)
    two = one.copy()
    want = one.copy()
    want[slots] = rows
    scatter_rows(one, slots, rows)
    scatter_rows(two, slots, rows, threads=2)
    np.testing.assert_array_equal(one, want)
    np.testing.assert_array_equal(two, want)
