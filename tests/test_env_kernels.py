"""The env front ends' per-step kernels give exactly what their numpy statements give; recycled outputs are
never written while someone holds them."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.env.batch_kernels import finish_step, prepare_actions, scatter_part
from agentsim_env.env.buffers import Recycled
from agentsim_env.motion.integrate import clip_box
from tests.reference.batch_kernels import (
    finish_step_reference,
    prepare_actions_reference,
    scatter_part_reference,
)
from tests.reference.motion import clip_box_reference

SPECIAL = np.array([-0.0, 0.0, -1.0, 1.0, -1.5, 1.5, 1e300, -1e300, np.nan, np.inf, -np.inf])


def _values(rng: np.random.Generator, shape: tuple[int, ...], bad: float) -> np.ndarray:
    a = rng.uniform(-2.0, 2.0, shape)
    pick = rng.random(shape) < 0.3
    a[pick] = rng.choice(SPECIAL[:8], int(pick.sum()))
    nan = rng.random(shape) < bad
    a[nan] = rng.choice(SPECIAL[8:], int(nan.sum()))
    return a


def _same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.dtype == b.dtype and a.shape == b.shape
    assert a.tobytes() == b.tobytes()


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None)
def test_prepare_actions_equals_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s, d = int(rng.integers(1, 30)), int(rng.integers(1, 6))
    a = _values(rng, (s, d), 0.02 if rng.random() < 0.5 else 0.0)
    alive = rng.random(s) < 0.8
    got, bad = prepare_actions(a, alive)
    want, want_bad = prepare_actions_reference(a, alive)
    assert bad == want_bad
    if bad < 0:
        _same(got, want)


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None)
def test_finish_step_equals_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    b, n, d = int(rng.integers(1, 6)), int(rng.integers(1, 6)), int(rng.integers(1, 5))
    alive = rng.random((b, n)) < 0.7
    acting = alive.reshape(-1).copy()
    term = acting & (rng.random(b * n) < 0.3)
    over = rng.random(b) < 0.3
    obs = rng.normal(size=(b * n, d)).astype(np.float32)
    alive2, obs2 = alive.copy(), obs.copy()
    trunc, done, n_done = finish_step(term, acting, over, alive, obs)
    trunc2, done2, n_done2 = finish_step_reference(term, acting, over, alive2, obs2)
    _same(trunc, trunc2)
    _same(done, done2)
    _same(alive, alive2)
    _same(obs, obs2)
    assert n_done == n_done2


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None)
def test_scatter_part_equals_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s, d = int(rng.integers(1, 30)), int(rng.integers(1, 6))
    idx = np.sort(rng.choice(s, int(rng.integers(1, s + 1)), replace=False)).astype(np.int64)
    vals = _values(rng, (idx.shape[0], d), 0.02 if rng.random() < 0.5 else 0.0)
    if rng.random() < 0.3:
        vals = vals.astype(np.float32)
    got = scatter_part(vals, idx, s, -1.0, 1.0)
    want = scatter_part_reference(vals, idx, s, -1.0, 1.0)
    assert (got is None) == (want is None)
    if got is not None and want is not None:
        _same(got, want)


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None)
def test_clip_box_equals_np_clip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pos = _values(rng, (int(rng.integers(0, 30)), 3), 0.05) * 60.0
    lo = rng.choice(np.array([-0.0, 0.0, -5.0, 3.0]), 3)
    hi = lo + rng.choice(np.array([0.0, 1.0, 50.0]), 3)
    a, b = pos.copy(), pos.copy()
    clip_box(a, lo, hi)
    clip_box_reference(b, lo, hi)
    _same(a, b)


def test_recycled_array_is_reused_only_when_nobody_holds_it() -> None:
    r = Recycled((3, 4), np.float32)
    first = r.get()
    second = r.get()
    assert second is not first  # held by the caller: a fresh one
    view = second[1:]
    del second
    third = r.get()
    assert third is not view.base  # a view keeps it
    address = third.__array_interface__["data"][0]
    del third
    assert r.get().__array_interface__["data"][0] == address  # dropped everywhere: reused
    assert first.shape == (3, 4)


def test_batched_observations_stay_valid_after_later_steps() -> None:
    from agentsim_env.env.vector import BatchedEnv

    env = BatchedEnv("navigation", 2, n_agents=3)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    held = []
    for _ in range(5):
        r = env.step(rng.uniform(-1, 1, (2, 3, env.act_dim)))
        held.append((r.obs, r.obs.copy()))
        env.step(rng.uniform(-1, 1, (2, 3, env.act_dim)))  # its result is dropped: its buffer is reused
    for obs, copy in held:
        np.testing.assert_array_equal(obs, copy)
