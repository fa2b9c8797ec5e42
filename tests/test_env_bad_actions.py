"""The action rule holds per agent, whatever the other agents send; tensors are read as numbers.

The rule (README, ``env.spaces.ACTION_RULE``): each part is real numbers (ints or floats; not bools) in exactly
the part's shape. Stacking every agent's part into one array must not let one agent's bools through because
the others send floats. A torch tensor (with ``requires_grad``, on any device, any real dtype) is read as its
values; a bool or complex tensor is refused like a bool or complex array, naming the agent.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.vector import BatchedEnv

torch = pytest.importorskip("torch")


def _env(fmt: str = "dict", **kw: Any) -> Any:
    env = agentsim_env.make("navigation", n_agents=4, comms={}, action_format=fmt, **kw)
    env.reset(seed=0)
    return env


def _actions(env: Any, seed: int = 0) -> dict[str, Any]:
    """Float64 actions of every live agent (the same for the same seed)."""
    rng = np.random.default_rng(seed)
    space = env.action_space(env.agents[0])
    if env.action_format == "flat":
        return {a: rng.uniform(-1, 1, space.shape) for a in env.agents}
    return {a: {k: rng.uniform(-1, 1, s.shape) for k, s in space.items()} for a in env.agents}


def _set(acts: dict[str, Any], agent: str, env: Any, value: Any, part: str = "motion") -> None:
    if env.action_format == "flat":
        acts[agent] = value
    else:
        acts[agent][part] = value


def _bool_like(env: Any, part: str) -> np.ndarray:
    space = env.action_space(env.agents[0])
    shape = space.shape if env.action_format == "flat" else space[part].shape
    return np.arange(int(np.prod(shape))).reshape(shape) % 2 == 0


# ------------------------------------------------------------------ bools among floats
@pytest.mark.parametrize("form", ["array", "list", "tensor"])
@pytest.mark.parametrize(("fmt", "part"), [("dict", "motion"), ("dict", "comm"), ("flat", "motion")])
def test_one_agent_sending_bools_is_refused_by_name(fmt: str, form: str, part: str) -> None:
    env = _env(fmt)
    pos = env.world.state.pos.copy()
    acts = _actions(env)
    bools = _bool_like(env, part)
    value = {"array": bools, "list": bools.tolist(), "tensor": torch.from_numpy(bools)}[form]
    _set(acts, "agent_2", env, value, part)
    with pytest.raises(ValueError) as info:
        env.step(acts)
    msg = str(info.value)
    assert "'agent_2'" in msg and "bool" in msg and "real numbers" in msg, msg
    if fmt == "dict":
        assert repr(part) in msg, msg
    np.testing.assert_array_equal(env.world.state.pos, pos)  # nothing moved
    env.step(_actions(env))  # the env keeps working


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_bools_in_the_first_or_last_agent_are_refused(fmt: str) -> None:
    env = _env(fmt)
    for agent in (env.agents[0], env.agents[-1]):
        acts = _actions(env)
        _set(acts, agent, env, _bool_like(env, "motion"))
        with pytest.raises(ValueError, match=f"'{agent}'.*bool"):
            env.step(acts)


def test_ints_and_floats_mixed_across_agents_are_accepted() -> None:
    env = _env()
    acts = _actions(env)
    acts["agent_1"]["motion"] = np.array([1, 0, -1], dtype=np.int8)
    acts["agent_3"]["motion"] = [0, 1, 0]
    env.step(acts)


def test_batched_env_refuses_bool_actions() -> None:
    env = BatchedEnv("navigation", 2, n_agents=3)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="actions must be real numbers.*bool"):
        env.step(np.ones((2, 3, env.act_dim), dtype=bool))
    env.step(np.zeros((2, 3, env.act_dim), dtype=np.int32))  # ints are real numbers


# ------------------------------------------------------------------ tensors
def _tensor(values: Any, **kw: Any) -> Any:
    return torch.tensor(np.asarray(values), **kw)


class _DeviceTensor:
    """Stands for a tensor on an accelerator: numpy cannot read it, ``.detach().cpu()`` can."""

    def __init__(self, values: Any) -> None:
        self._t = torch.tensor(np.asarray(values, dtype=np.float32), requires_grad=True)

    def __array__(self, *args: Any, **kw: Any) -> np.ndarray:
        raise TypeError("can't convert cuda:0 device type tensor to numpy. Use Tensor.cpu() first.")

    def __len__(self) -> int:
        return len(self._t)

    def detach(self) -> _DeviceTensor:
        return self

    def cpu(self) -> Any:
        return self._t.detach()


def _values(t: Any) -> np.ndarray:
    """What a tensor holds, as float64 numpy (bfloat16 through float32, which holds it exactly)."""
    t = t.detach().cpu()
    return (t.float() if t.dtype == torch.bfloat16 else t).numpy().astype(np.float64)


TENSOR_FORMS = {
    "requires_grad": lambda v: _tensor(v, dtype=torch.float32, requires_grad=True),
    "float64": lambda v: _tensor(v, dtype=torch.float64),
    "float16": lambda v: _tensor(v, dtype=torch.float16),
    "bfloat16": lambda v: _tensor(v, dtype=torch.float32).to(torch.bfloat16),
    "int64": lambda v: _tensor(np.round(v), dtype=torch.int64),
    "requires_grad view": lambda v: _tensor(np.tile(v, 2), dtype=torch.float32, requires_grad=True)[::2] * 1.0,
    "device": _DeviceTensor,
}


@pytest.mark.parametrize("fmt", ["dict", "flat"])
@pytest.mark.parametrize("who", ["one", "all"])
@pytest.mark.parametrize("form", list(TENSOR_FORMS))
def test_tensor_actions_step_like_their_values(fmt: str, who: str, form: str) -> None:
    make = TENSOR_FORMS[form]
    env, twin = _env(fmt), _env(fmt)
    for seed in range(3):
        acts = _actions(env, seed)
        # the values the tensor holds, as the env will read them
        held = {
            a: {k: _values(make(v)) for k, v in x.items()} if fmt == "dict" else _values(make(x))
            for a, x in acts.items()
        }
        names = env.agents if who == "all" else ["agent_1"]
        sent = {
            a: ({k: make(v) for k, v in x.items()} if fmt == "dict" else make(x)) if a in names else held[a]
            for a, x in acts.items()
        }
        got = env.step(sent)
        want = twin.step(held)
        np.testing.assert_array_equal(env.world.state.pos, twin.world.state.pos)
        assert got[1] == want[1]


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_complex_tensor_is_refused_by_name(fmt: str) -> None:
    env = _env(fmt)
    acts = _actions(env)
    value = acts["agent_3"]["motion"] if fmt == "dict" else acts["agent_3"]
    _set(acts, "agent_3", env, torch.tensor(value, dtype=torch.complex64, requires_grad=True))
    with pytest.raises(ValueError, match="'agent_3'.*real numbers.*complex"):
        env.step(acts)


def test_tensor_of_the_wrong_shape_names_the_agent() -> None:
    env = _env()
    acts = _actions(env)
    acts["agent_0"]["motion"] = torch.zeros(4, requires_grad=True)
    with pytest.raises(ValueError, match=r"'agent_0'.*shape \(3,\)"):
        env.step(acts)


def test_batched_env_reads_tensor_actions() -> None:
    env, twin = BatchedEnv("navigation", 2, n_agents=3), BatchedEnv("navigation", 2, n_agents=3)
    env.reset(seed=0)
    twin.reset(seed=0)
    a = np.random.default_rng(0).uniform(-1, 1, (2, 3, env.act_dim)).astype(np.float32)
    got = env.step(torch.tensor(a, requires_grad=True))
    want = twin.step(a)
    np.testing.assert_array_equal(got.obs, want.obs)
    env.step(_DeviceTensor(a))
    with pytest.raises(ValueError, match="actions must be real numbers.*bool"):
        env.step(torch.zeros((2, 3, env.act_dim), dtype=torch.bool))
