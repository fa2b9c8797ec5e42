"""One env, two threads: a call that overlaps another call of the same env is refused, naming both calls.

An env is not thread-safe (its world is one set of arrays). Handing it from one thread to another is fine;
calling ``reset``, ``step`` or ``close`` while another thread is inside one of them raises ``RuntimeError``
before anything changes, instead of interleaving two steps silently.
"""

from __future__ import annotations

import copy
import pickle
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.vector import BatchedEnv


def _parallel() -> Any:
    env = agentsim_env.make("navigation", n_agents=4)
    env.reset(seed=0)
    return env


def _batched() -> BatchedEnv:
    env = BatchedEnv("navigation", 2, n_agents=4)
    env.reset(seed=0)
    return env


def _zero_actions(env: Any) -> Any:
    if isinstance(env, BatchedEnv):
        return np.zeros((env.n_worlds, env.n_agents, env.act_dim))
    return {a: {k: np.zeros(s.shape) for k, s in env.action_space(a).items()} for a in env.agents}


def _hold_first_step(env: Any) -> tuple[threading.Event, threading.Event]:
    """Make the env's first ``_step_core`` wait inside the call until released; later calls run through.

    Returns:
        ``inside`` (set once the first call is waiting) and ``release`` (set it to let the first call finish).
    """
    inside, release = threading.Event(), threading.Event()
    original = env._step_core
    calls = []

    def held(*args: Any) -> Any:
        calls.append(1)
        if len(calls) == 1:
            inside.set()
            assert release.wait(10.0)
        return original(*args)

    env._step_core = held
    return inside, release


CALLS: dict[str, Callable[[Any], Any]] = {
    "step": lambda env: env.step(_zero_actions(env)),
    "reset": lambda env: env.reset(seed=1),
}


@pytest.mark.parametrize("make", [_parallel, _batched], ids=["ParallelEnv", "BatchedEnv"])
@pytest.mark.parametrize("second", ["step", "reset"])
def test_call_during_a_step_of_another_thread_is_refused(make: Callable[[], Any], second: str) -> None:
    env = make()
    inside, release = _hold_first_step(env)
    errors: list[BaseException] = []

    def first() -> None:
        try:
            env.step(_zero_actions(env))
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors.append(exc)

    worker = threading.Thread(target=first, name="stepper")
    worker.start()
    try:
        assert inside.wait(10.0)
        pos = env.world.state.pos.copy()
        tick = env.world.tick
        with pytest.raises(RuntimeError) as info:
            CALLS[second](env)
        msg = str(info.value)
        assert f"{second}() called from thread 'MainThread'" in msg, msg
        assert "while step() runs in thread 'stepper'" in msg, msg
        # the refused call changed nothing
        np.testing.assert_array_equal(env.world.state.pos, pos)
        assert env.world.tick == tick
    finally:
        release.set()
        worker.join(10.0)
    assert not errors, errors
    # the first call finished normally and released the env: every thread may use it again
    CALLS["step"](env)
    other = threading.Thread(target=lambda: CALLS["step"](env), name="next-owner")
    other.start()
    other.join(10.0)
    CALLS["reset"](env)


def test_close_during_a_step_is_refused() -> None:
    env = _parallel()  # BatchedEnv holds nothing to close
    inside, release = _hold_first_step(env)
    worker = threading.Thread(target=lambda: env.step(_zero_actions(env)), name="stepper")
    worker.start()
    try:
        assert inside.wait(10.0)
        with pytest.raises(RuntimeError, match=r"close\(\) called from thread 'MainThread' while step\(\) runs"):
            env.close()
    finally:
        release.set()
        worker.join(10.0)
    env.close()


@pytest.mark.parametrize("make", [_parallel, _batched], ids=["ParallelEnv", "BatchedEnv"])
def test_a_failed_call_releases_the_env(make: Callable[[], Any]) -> None:
    env = make()
    with pytest.raises(ValueError):
        env.step("not actions" if not isinstance(env, BatchedEnv) else np.zeros(3))
    worker = threading.Thread(target=lambda: CALLS["step"](env))
    worker.start()
    worker.join(10.0)
    CALLS["step"](env)  # no "runs in thread" error: the failed call let go


@pytest.mark.parametrize("make", [_parallel, _batched], ids=["ParallelEnv", "BatchedEnv"])
def test_env_with_the_guard_still_copies_and_pickles(make: Callable[[], Any]) -> None:
    env = make()
    for clone in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        CALLS["step"](clone)
        CALLS["step"](env)
