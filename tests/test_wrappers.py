"""The wrapper bases (``agentsim_env.wrappers``): every public name of the env is forwarded explicitly, values are
the env's own, wrappers nest, and the recorder's and the video's front ends built on them pass PettingZoo's
``parallel_api_test`` alone and nested."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.distributed import DistributedBatchedEnv
from agentsim_env.distributed import make as make_sharded
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.recorder import RecordedBatchedEnv, RecordedParallelEnv, record
from agentsim_env.recorder.read import Store
from agentsim_env.render.record_video import RecordVideo
from agentsim_env.wrappers import BatchedEnvWrapper, ParallelEnvWrapper

CONFIG: dict[str, Any] = {"n_agents": 3, "max_steps": 8}

# Public names of an env that the base does not forward, each with its reason. Empty for the plain envs: a new
# public method or attribute on AgentSimParallelEnv or BatchedEnv fails the tests below until the base forwards it
# (or it is listed here, commented).
PARALLEL_EXCLUDED: dict[str, str] = {}
BATCHED_EXCLUDED: dict[str, str] = {}
# the sharded envs' own extras: reached through ``unwrapped`` (a wrapper of any env forwards the common API only)
SHARDED_EXCLUDED = {
    "coordinator": "sharded env only",
    "shards": "sharded env only",
    "add_objects": "sharded only",
}


def public_names(obj: Any) -> set[str]:
    """The public names of an object (its class's and its instance's)."""
    return {n for n in dir(obj) if not n.startswith("_")}


def forwarded_by(base: type) -> set[str]:
    """Names written on the base itself (inherited defaults, e.g. ParallelEnv's own ``unwrapped``, do not count)."""
    return {n for n in vars(base) if not n.startswith("_")}


def assert_same_values(wrapper: Any, env: Any, names: set[str]) -> None:
    """Every forwarded attribute that is not a method reads the env's own object (or its equal int/bool)."""
    for name in sorted(names):
        got, want = getattr(wrapper, name), getattr(env, name)
        if callable(want) and not isinstance(want, np.ndarray):
            continue
        if name == "unwrapped":
            assert got is env.unwrapped
        elif isinstance(want, (bool, int, np.integer)):
            assert got == want and type(got) is type(want), name
        else:
            assert got is want, name


# ------------------------------------------------------------------------------------------ forwarding
def test_the_parallel_base_forwards_every_public_name_of_the_env() -> None:
    env = agentsim_env.make("navigation", **CONFIG)
    missing = public_names(env) - forwarded_by(ParallelEnvWrapper) - set(PARALLEL_EXCLUDED)
    assert not missing, f"ParallelEnvWrapper does not forward {sorted(missing)}: add them (or exclude, commented)"
    wrapper = ParallelEnvWrapper(env)
    wrapper.reset(seed=0)
    assert_same_values(wrapper, env, public_names(env) - set(PARALLEL_EXCLUDED))
    assert wrapper.num_agents == env.num_agents == 3 and wrapper.max_num_agents == 3


def test_the_batched_base_forwards_every_public_name_of_the_env() -> None:
    env = BatchedEnv("navigation", 2, **CONFIG)
    missing = public_names(env) - forwarded_by(BatchedEnvWrapper) - set(BATCHED_EXCLUDED)
    assert not missing, f"BatchedEnvWrapper does not forward {sorted(missing)}: add them (or exclude, commented)"
    wrapper = BatchedEnvWrapper(env)
    wrapper.reset(seed=0)
    wrapper.step(np.zeros((2, 3, env.act_dim)))
    assert_same_values(wrapper, env, public_names(env) - set(BATCHED_EXCLUDED))
    assert wrapper.steps.tolist() == [1, 1]


def test_the_bases_forward_the_sharded_envs_common_api() -> None:
    par = make_sharded("navigation", shards=2, backend="local", n_agents=40, collisions=False)
    bat = DistributedBatchedEnv("navigation", 2, backend="local", n_agents=40, collisions=False)
    try:
        for env, base in ((par, ParallelEnvWrapper), (bat, BatchedEnvWrapper)):
            missing = public_names(env) - forwarded_by(base) - set(SHARDED_EXCLUDED)
            assert not missing, f"{base.__name__} does not forward {sorted(missing)}"
            assert base(env).unwrapped.coordinator is env.coordinator
    finally:
        par.close()
        bat.close()


def test_wrappers_hold_none_of_the_envs_state() -> None:
    """No ``__getattr__`` fallback and no copy of the env's ``__dict__``: private names are not reachable."""
    for cls in (ParallelEnvWrapper, BatchedEnvWrapper, RecordedParallelEnv, RecordedBatchedEnv, RecordVideo):
        assert all("__getattr__" not in vars(k) for k in cls.__mro__ if k is not object), cls
    env = agentsim_env.make("navigation", **CONFIG)
    wrapper = ParallelEnvWrapper(env)
    assert not set(vars(wrapper)) & set(vars(env)) - {"env"}
    with pytest.raises(AttributeError):
        wrapper._index  # noqa: B018 - reading it is the test


def test_a_bare_wrapper_gives_the_envs_results() -> None:
    plain, wrapped = (
        agentsim_env.make("navigation", **CONFIG),
        ParallelEnvWrapper(agentsim_env.make("navigation", **CONFIG)),
    )
    oa, _ = plain.reset(seed=4)
    ob, _ = wrapped.reset(seed=4)
    while plain.agents:
        acts = {a: plain.action_space(a).sample() for a in plain.agents}
        ra, rb = plain.step(acts), wrapped.step(acts)
        assert ra[1] == rb[1] and ra[2] == rb[2] and ra[3] == rb[3]
        assert wrapped.agents == plain.agents
    assert oa.keys() == ob.keys()
    np.testing.assert_array_equal(wrapped.state(), plain.state())
    got = wrapped.rollout("go_to_goal", 8, seed=1)
    want = agentsim_env.make("navigation", **CONFIG).rollout("go_to_goal", 8, seed=1)
    np.testing.assert_array_equal(got.returns, want.returns)


def test_bad_envs_are_named() -> None:
    with pytest.raises(ValueError, match="env must be a PettingZoo ParallelEnv.*got dict"):
        ParallelEnvWrapper({})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="env must be a BatchedEnv.*got dict without"):
        BatchedEnvWrapper({})


# ------------------------------------------------------------------------------------------ nesting
class CountingBatched(BatchedEnvWrapper):
    """A wrapper that counts steps and closes (to see a wrapper inside the recorder)."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.stepped = self.closed = 0

    def step(self, actions: np.ndarray) -> Any:
        """Count, then step."""
        self.stepped += 1
        return self.env.step(actions)

    def close(self) -> None:
        """Count, then close."""
        self.closed += 1
        self.env.close()


def test_a_recorded_batched_env_nests_and_closes_what_it_wraps(tmp_path: Path) -> None:
    inner = BatchedEnv("navigation", 2, **CONFIG)
    counting = CountingBatched(inner)
    env = record(counting, tmp_path / "b.db")
    assert isinstance(env, RecordedBatchedEnv) and env.unwrapped is inner
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros((2, 3, env.act_dim)))
    env.close()
    assert counting.stepped == 3 and counting.closed == 1
    with Store(tmp_path / "b.db") as store:
        assert store.steps().index.get_level_values("step").max() == 3


def test_sb3_drives_a_recorded_batched_env(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from agentsim_env.env.sb3 import AgentSimVecEnv

    batch = record(BatchedEnv("navigation", 2, **CONFIG), tmp_path / "v.db")
    vec = AgentSimVecEnv("navigation", 2, batch=batch)
    obs = vec.reset()
    assert obs.shape == (6, batch.obs_dim)
    vec.step(np.zeros((6, batch.act_dim), dtype=np.float32))
    vec.close()
    with Store(tmp_path / "v.db") as store:
        assert store.steps().index.get_level_values("step").max() == 1


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pettingzoo.test imports its old API
@pytest.mark.parametrize("stack", ["record", "video", "record(video)", "video(record)"])
def test_wrapped_envs_pass_the_parallel_api_test(tmp_path: Path, stack: str) -> None:
    from pettingzoo.test import parallel_api_test

    base = agentsim_env.make("navigation", n_agents=2, max_steps=20, render_mode="rgb_array")
    db, videos = tmp_path / "run.db", tmp_path / "videos"

    def video(env: Any) -> RecordVideo:
        return RecordVideo(env, videos, every_n=1000, fmt="gif")

    env: Any = {
        "record": lambda: record(base, db),
        "video": lambda: video(base),
        "record(video)": lambda: record(video(base), db),
        "video(record)": lambda: video(record(base, db)),
    }[stack]()
    assert env.unwrapped is base and env.metadata is base.metadata
    parallel_api_test(env, num_cycles=30)
    assert env.agents == base.agents and env.world is base.world
    env.close()
    if "video" in stack:
        assert sorted(p.name for p in videos.iterdir()) == ["rl-video-episode-0.gif"]
    if "record" in stack:
        with Store(db) as store:
            assert len(store.steps()) > 0


def test_a_nested_recorder_rolls_out_through_every_step(tmp_path: Path) -> None:
    """``record(video(env)).rollout`` runs through the recorder's step, which steps the video wrapper: filmed."""
    base = agentsim_env.make("navigation", n_agents=2, max_steps=5, render_mode="rgb_array")
    film = RecordVideo(base, tmp_path / "v", fmt="gif")
    env = record(film, tmp_path / "r.db")
    got = env.rollout("go_to_goal", 5, seed=3)
    env.close()
    want = agentsim_env.make("navigation", n_agents=2, max_steps=5).rollout("go_to_goal", 5, seed=3)
    np.testing.assert_array_equal(got.returns, want.returns)
    assert got.steps == want.steps
    assert [p.name for p in film.written] == ["rl-video-episode-0.gif"]
    assert isinstance(env, RecordedParallelEnv)
