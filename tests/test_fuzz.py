"""Hypothesis fuzz over every registered scenario: random configs inside the documented ranges, random episodes.

For each scenario in ``agentsim_env.list_scenarios()`` a strategy below draws a config inside the ranges that
the config docstrings and validators document (every field of the scenario, sub-config dicts included), with
the range endpoints and other edge values drawn often. The example then builds the env, with
``check_finite=True`` half of the time when ``make`` accepts it. A ``ValueError`` of the config checks at
construction is allowed: the example is rejected with ``assume`` and counted. Any other exception fails, and so
does a ``ValueError`` raised inside the probe episode that construction runs to measure the spaces (a reset and
a step: that is an episode failing, not a config rejected). The env is then reset with a random seed and
stepped with random actions from the action spaces (dict and flat formats; with comms on, also ``send_message``
and ``assign_group`` from code) until every agent is done, which must happen by ``max_steps``; half of the
examples run a second episode. Checked on every step: no exception, no ``RuntimeWarning`` (turned into an error:
a silent NaN usually shows up as one), every observation inside its observation space and finite, every reward
finite, every info value a finite number, and (half of the time) ``state()`` finite and inside
``state_space``. A quarter of the examples run the array API instead (``BatchedEnv``, 1-3 worlds, for
``max_steps + 3`` steps, so across an automatic reset), with the same checks on its arrays.

A scenario registered without a strategy here fails the test: add one to ``STRATEGIES``.

Sizes: the fast profile (``make test``) runs ``FAST_EXAMPLES`` examples per scenario, derandomized (the same
examples every run), in about half a minute on 2 cores. ``AGENTSIM_FUZZ_EXAMPLES=N`` (``make fuzz``: 10,000)
selects the long profile instead: about N examples in all, split over the scenarios, randomized. Rejected
examples come on top (hypothesis counts valid examples only). A failure is shrunk to a minimal config, printed
as ``Draw 1 (config)`` with the seeds and the ``agentsim_env.make`` / ``BatchedEnv`` call that reproduces it.

Counts: every example that built an env and one rejected at construction is counted per scenario (the runs
hypothesis makes while shrinking a failure included). A
single-process run (``make fuzz``) prints them in a terminal-summary section "agentsim fuzz" (with the
commonest rejection messages); under pytest-xdist use ``--hypothesis-show-statistics``, whose "Events" lines
carry the same counts as percentages. Each test also records them as the ``fuzz`` user property (junit XML).

Ranges not bounded by the docs get a generous soft cap here (noted at the strategy), and a few sizes are kept
small for speed, not because larger values are invalid: at most 12 agents, episodes of at most 40 steps, at most
about 3,000 obstacles per world, zones of at most 300 m radius holding 1-12 sensors each, WSN coverage lattices
at least 0.5 m apart, at most 4 rings of rays (64 with at most 4 azimuths) and 1,024 azimuths with at most 2
rings.
"""

from __future__ import annotations

import functools
import inspect
import math
import os
import re
import warnings
from collections import Counter, defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

import agentsim_env
from tests.fuzz_configs import STRATEGIES

# ----------------------------------------------------------------------------------------------- profiles
FAST_EXAMPLES = 100
"""Examples per scenario of the fast profile (``make test``)."""
ENV_VAR = "AGENTSIM_FUZZ_EXAMPLES"
"""Total examples over all scenarios of the long profile (``make fuzz`` sets 10,000)."""

_COMMON = {
    "deadline": None,
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.filter_too_much,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
    "print_blob": True,
}
settings.register_profile("agentsim-fuzz", max_examples=FAST_EXAMPLES, derandomize=True, **_COMMON)


def _long_examples() -> int | None:
    raw = os.environ.get(ENV_VAR, "").strip()
    if not raw:
        return None
    total = int(raw)
    if total < 1:
        raise ValueError(f"{ENV_VAR} must be a positive integer, got {raw!r}")
    return total


_TOTAL = _long_examples()
_N_SCENARIOS = len(agentsim_env.list_scenarios())
settings.register_profile(
    "agentsim-fuzz-long",
    max_examples=max(1, math.ceil((_TOTAL or 10_000) / _N_SCENARIOS)),
    derandomize=False,
    **_COMMON,
)
PROFILE = "agentsim-fuzz-long" if _TOTAL is not None else "agentsim-fuzz"

# ----------------------------------------------------------------------------------------------- counting
_STATS: dict[str, Counter[str]] = defaultdict(Counter)
_REJECTIONS: dict[str, Counter[str]] = defaultdict(Counter)


def _reason(exc: BaseException) -> str:
    """A rejection message with its numbers blanked, so equal causes count together."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return re.sub(r"[-+]?\d[\d.,_]*(e[-+]?\d+)?", "#", text)[:110]


class _FuzzSummary:
    """Prints the example counts at the end of a single-process session (pytest-xdist workers cannot)."""

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not _STATS:
            return
        tr = terminalreporter
        tr.section("agentsim fuzz")
        total = Counter[str]()
        for name in sorted(_STATS):
            c = _STATS[name]
            total.update(c)
            tr.write_line(
                f"{name:12s} {c['built']:6d} examples run, {c['rejected']:5d} rejected at construction "
                f"(ValueError), {c['steps']:7d} steps, {c['batched']:5d} via BatchedEnv, "
                f"{c['check_finite']:5d} with check_finite=True"
            )
        tr.write_line(
            f"{'total':12s} {total['built']:6d} examples run, {total['rejected']:5d} rejected at construction, "
            f"{total['steps']:7d} steps"
        )
        for name in sorted(_REJECTIONS):
            for reason, n in _REJECTIONS[name].most_common(8):
                tr.write_line(f"  rejected {name}: {n:4d} x {reason}")


@pytest.fixture(scope="session", autouse=True)
def _fuzz_summary_plugin(request: pytest.FixtureRequest) -> None:
    pm = request.config.pluginmanager
    if not hasattr(request.config, "workerinput") and not pm.has_plugin("agentsim-fuzz-summary"):
        pm.register(_FuzzSummary(), "agentsim-fuzz-summary")


# ----------------------------------------------------------------------------------------------- checks
@functools.cache
def check_finite_supported() -> bool:
    """Whether ``agentsim_env.make`` accepts the ``check_finite`` keyword (being added to the env)."""
    try:
        env = agentsim_env.make("rendezvous", n_agents=1, max_steps=1, check_finite=True)
    except (TypeError, ValueError) as exc:
        if "check_finite" in str(exc):
            return False
        raise
    env.close()
    return True


@functools.cache
def batched_check_finite_supported() -> bool:
    """Whether ``BatchedEnv`` accepts the ``check_finite`` keyword."""
    from agentsim_env.env.vector import BatchedEnv

    return "check_finite" in inspect.signature(BatchedEnv.__init__).parameters


def check_box(box: spaces.Box, x: Any, where: str) -> None:
    """``x`` is a finite array of the box's shape and dtype inside its bounds (the message says where not)."""
    assert isinstance(x, np.ndarray), f"{where}: expected an ndarray, got {type(x).__name__}"
    assert x.shape == box.shape, f"{where}: shape {x.shape}, space {box.shape}"
    assert x.dtype == box.dtype, f"{where}: dtype {x.dtype}, space {box.dtype}"
    bad = ~np.isfinite(x)
    assert not bad.any(), f"{where}: non-finite values at {np.argwhere(bad)[:4].tolist()}: {x[bad][:4]}"
    out = (x < box.low) | (x > box.high)
    if out.any():
        idx = np.argwhere(out)[:4]
        vals = [(i.tolist(), float(x[tuple(i)]), float(box.low[tuple(i)]), float(box.high[tuple(i)])) for i in idx]
        raise AssertionError(f"{where}: outside the space (index, value, low, high): {vals}")


def check_obs(space: spaces.Space, obs: Any, where: str) -> None:
    """An observation is finite and inside its space (``space.contains`` and a precise diagnosis)."""
    if isinstance(space, spaces.Dict):
        assert isinstance(obs, dict), f"{where}: expected a dict, got {type(obs).__name__}"
        assert set(obs) == set(space.spaces), f"{where}: parts {sorted(obs)}, space {sorted(space.spaces)}"
        for k, sub in space.spaces.items():
            check_box(sub, obs[k], f"{where}[{k!r}]")
    else:
        check_box(space, obs, where)
    assert space.contains(obs), f"{where}: space.contains() is False"


def check_number(x: Any, where: str) -> None:
    """A finite Python or numpy real number (not a bool)."""
    assert isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_)), (
        f"{where}: expected a number, got {type(x).__name__} {x!r}"
    )
    assert math.isfinite(x), f"{where}: non-finite {x!r}"


def random_part(rng: np.random.Generator, box: spaces.Box) -> np.ndarray:
    """A random point of an action box: uniform, with about 1 in 10 values at -1, 0 or 1 (box in [-1, 1])."""
    x = rng.uniform(box.low, box.high)
    edge = rng.random(box.shape) < 0.1
    x[edge] = rng.choice([-1.0, 0.0, 1.0], int(edge.sum()))
    return np.clip(x, box.low, box.high).astype(box.dtype)


def random_action(rng: np.random.Generator, space: spaces.Space) -> Any:
    """A random action of a Dict-of-Box or Box action space."""
    if isinstance(space, spaces.Dict):
        return {k: random_part(rng, sub) for k, sub in space.spaces.items()}
    return random_part(rng, space)


def random_payload(rng: np.random.Generator, d: int) -> np.ndarray:
    """``d`` finite floats (``send_message`` documents no range): mostly in [-1, 1], sometimes large."""
    scale = rng.choice([1.0, 1.0, 1.0, 1e3, 1e5, 1e30])
    return rng.uniform(-1.0, 1.0, d) * scale


# ------------------------------------------------------------------------------------------------ the runs
def run_parallel(env: Any, seed: int, rng: np.random.Generator, extras: bool, state: bool) -> int:
    """One episode of the ParallelEnv with every check; returns the steps taken."""
    obs, infos = env.reset(seed=seed)
    assert set(obs) == set(env.agents) == set(infos), "reset: observations, infos and agents differ"
    for a, o in obs.items():
        check_obs(env.observation_space(a), o, f"reset obs of {a}")
        for k, v in infos[a].items():
            check_number(v, f"reset info {k!r} of {a}")
    comms = env.world.comms is not None
    max_steps = env.scenario.max_steps
    steps = 0
    while env.agents and steps < max_steps:
        live = list(env.agents)
        actions = {a: random_action(rng, env.action_space(a)) for a in live}
        if comms and extras:
            code_api(env, rng, live)
        obs, rewards, terms, truncs, infos = env.step(actions)
        steps += 1
        where = f"step {steps}"
        assert set(obs) == set(rewards) == set(terms) == set(truncs) == set(infos) == set(live), (
            f"{where}: the returned dicts do not hold exactly the agents that acted"
        )
        for a in live:
            check_obs(env.observation_space(a), obs[a], f"{where}: obs of {a}")
            check_number(rewards[a], f"{where}: reward of {a}")
            assert isinstance(terms[a], bool) and isinstance(truncs[a], bool), f"{where}: flags of {a}"
            for k, v in infos[a].items():
                check_number(v, f"{where}: info {k!r} of {a}")
        assert set(env.agents) == {a for a in live if not (terms[a] or truncs[a])}, f"{where}: live agents"
        if state:
            s = env.state()
            check_box(env.state_space, np.asarray(s), f"{where}: state()")
    assert not env.agents, f"agents {env.agents[:3]} still live after max_steps = {max_steps} steps"
    return steps


def code_api(env: Any, rng: np.random.Generator, live: list[str]) -> None:
    """``send_message`` (unicast and group) and ``assign_group`` from code, on live agents."""
    d = env.world.comms.cfg.payload_dim
    for _ in range(int(rng.integers(0, 3))):
        sender = live[int(rng.integers(len(live)))]
        groups = np.unique(env.world.state.group[env.world.state.group >= 0]).tolist()
        if groups and rng.random() < 0.5:
            env.send_message(sender, random_payload(rng, d), group=int(rng.choice(groups)))
        else:
            env.send_message(sender, random_payload(rng, d), to=live[int(rng.integers(len(live)))])
    if rng.random() < 0.3:  # group ids run from -1 (none) to n_agents - 1
        env.assign_group(live[int(rng.integers(len(live)))], int(rng.integers(-1, env.scenario.n_agents)))


def run_batched(env: Any, seed: int, rng: np.random.Generator) -> int:
    """``max_steps + 3`` steps of the array API (across an automatic reset) with every check; returns steps."""
    from agentsim_env.env.spaces import observation_space_for

    b, n = env.n_worlds, env.n_agents
    box = observation_space_for(env.scenario.obs_parts(), "flat")
    obs = env.reset(seed=seed)
    assert obs.shape == (b, n, env.obs_dim) and obs.dtype == np.float32
    for w in range(b):
        for i in range(n):
            check_box(box, obs[w, i], f"reset obs of world {w} agent {i}")
    steps = env.scenario.max_steps + 3
    for t in range(1, steps + 1):
        actions = rng.uniform(-1.0, 1.0, (b, n, env.act_dim))
        alive = env.alive.copy()
        res = env.step(actions)
        for w in range(b):
            for i in range(n):
                if alive[w, i] or res.reset_worlds[w]:  # dead agents of running worlds read zeros
                    check_box(box, res.obs[w, i], f"step {t}: obs of world {w} agent {i}")
                if res.reset_worlds[w]:
                    check_box(box, res.final_obs[w, i], f"step {t}: final_obs of world {w} agent {i}")
        assert np.isfinite(res.rewards).all(), f"step {t}: non-finite rewards {res.rewards}"
        for k, v in res.info.items():
            assert v.shape == (b, n) and np.isfinite(v).all(), f"step {t}: info {k!r} {v}"
    return steps


PROBE_FRAMES = frozenset({"reset_worlds", "run_step", "reset_world", "score", "observe", "observation"})
"""Functions of a probe episode: construction measures the spaces on one (``Scenario.spec``)."""


def build_or_reject(name: str, make: Callable[[], Any]) -> Any:
    """Build the env; a ``ValueError`` of the config checks rejects the example (counted), anything else fails.

    Construction also runs a probe episode (a reset and a step, to measure the spaces): a ``ValueError`` raised
    inside it is a failure of that episode, not a rejected config, and fails the example.
    """
    try:
        return make()
    except ValueError as exc:
        tb, frames = exc.__traceback__, set()
        while tb is not None:
            frames.add(tb.tb_frame.f_code.co_name)
            tb = tb.tb_next
        if frames & PROBE_FRAMES:
            raise
        _STATS[name]["rejected"] += 1
        reason = _reason(exc)
        _REJECTIONS[name][reason] += 1
        event(f"rejected at construction: {reason}")
        assume(False)


@pytest.fixture
def _record(request: pytest.FixtureRequest, record_property: Callable[[str, Any], None]) -> Any:
    name = request.node.callspec.params["name"]
    before = Counter(_STATS[name])
    yield
    delta = {k: v - before.get(k, 0) for k, v in _STATS[name].items()}
    record_property("fuzz", delta)


# ------------------------------------------------------------------------------------------------- tests
def test_every_registered_scenario_has_a_strategy() -> None:
    missing = sorted(set(agentsim_env.list_scenarios()) - set(STRATEGIES))
    assert not missing, f"scenarios without a fuzz strategy in tests/test_fuzz.py: {missing}; add one"


@pytest.mark.parametrize("name", agentsim_env.list_scenarios())
@settings(settings.get_profile(PROFILE))
@given(data=st.data())
def test_fuzz_scenario(name: str, data: st.DataObject, _record: None) -> None:
    if name not in STRATEGIES:
        pytest.fail(f"scenario {name!r} has no fuzz strategy in tests/test_fuzz.py STRATEGIES; add one")
    config = data.draw(STRATEGIES[name], label="config")
    seed = data.draw(st.integers(0, 2**32 - 1), label="seed")
    action_seed = data.draw(st.integers(0, 2**32 - 1), label="action_seed")
    api = data.draw(st.sampled_from(["parallel", "parallel", "parallel", "batched"]), label="api")
    rng = np.random.default_rng(action_seed)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        if api == "batched":
            n_worlds = data.draw(st.integers(1, 3), label="n_worlds")
            from agentsim_env.env.vector import BatchedEnv

            kw = dict(config)
            if batched_check_finite_supported() and data.draw(st.booleans(), label="check_finite"):
                kw["check_finite"] = True
            note(f"BatchedEnv({name!r}, {n_worlds}, **{kw!r})")
            benv = build_or_reject(name, lambda: BatchedEnv(name, n_worlds, **kw))
            _STATS[name]["built"] += 1
            _STATS[name]["check_finite"] += "check_finite" in kw
            _STATS[name]["batched"] += 1
            event("built: BatchedEnv")
            _STATS[name]["steps"] += run_batched(benv, seed, rng)
            return
        env_kw = {
            "obs_format": data.draw(st.sampled_from(["dict", "flat"]), label="obs_format"),
            "action_format": data.draw(st.sampled_from(["dict", "flat"]), label="action_format"),
        }
        if check_finite_supported() and data.draw(st.booleans(), label="check_finite"):
            env_kw["check_finite"] = True
        extras = data.draw(st.booleans(), label="send_message/assign_group")
        state = data.draw(st.booleans(), label="check state()")
        note(f"agentsim_env.make({name!r}, **{ {**config, **env_kw}!r})")
        env = build_or_reject(name, lambda: agentsim_env.make(name, **config, **env_kw))
        _STATS[name]["built"] += 1
        _STATS[name]["check_finite"] += "check_finite" in env_kw
        event("built: ParallelEnv")
        try:
            _STATS[name]["steps"] += run_parallel(env, seed, rng, extras, state)
            if data.draw(st.booleans(), label="second episode"):  # a reset after a finished episode
                _STATS[name]["steps"] += run_parallel(env, seed + 1, rng, extras, state)
        finally:
            env.close()
