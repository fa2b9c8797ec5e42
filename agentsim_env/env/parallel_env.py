"""The PettingZoo ParallelEnv around a scenario (the only module that imports pettingzoo).

``step`` reads as the pipeline of DESIGN §4: validate and decode actions (1), run the world pipeline (2-8),
let the scenario score (9), then build the per-agent dicts once from arrays.
"""

from __future__ import annotations

import importlib.util
import operator
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec, parallel_to_aec_wrapper

from agentsim_env.core.pipeline import EpisodeSeeds
from agentsim_env.core.threads import check_num_threads
from agentsim_env.core.validation import check_choice
from agentsim_env.env.agent_dicts import per_agent, rows, stay_dicts
from agentsim_env.env.batch_kernels import scatter_part
from agentsim_env.env.buffers import Recycled
from agentsim_env.env.finite import assert_finite, check_finite_default
from agentsim_env.env.guard import CallGuard
from agentsim_env.env.messaging import MessageCalls
from agentsim_env.env.rollout import RolloutCallback, RolloutResult, run_rollout
from agentsim_env.env.spaces import (
    FORMATS,
    action_space_for,
    flat_layout,
    observation_space_for,
    split_action,
    stack_rows,
)
from agentsim_env.scenarios.base import Scenario, reset_worlds, run_step
from agentsim_env.scenarios.flat_layout import flat_parts
from agentsim_env.scenarios.registry import make_scenario

RENDER_MODES = ("human", "rgb_array", "web")
_MODE_NEEDS = {
    "human": "pygame",
    "web": "websockets",
}  # the package of the extra a mode needs (render, viewer)
ENDED_AGENTS = ("leave", "stay")
"""What becomes of an agent that ends before its episode does (``ended_agents``): ``"leave"`` (PettingZoo's rule:
it leaves ``agents``) or ``"stay"`` (it stays, observing zeros with reward 0, until the episode ends)."""


def available_render_modes() -> list[str]:
    """The render modes that can start in this installation, in ``RENDER_MODES`` order (``metadata``'s list).

    ``"human"`` needs the ``render`` extra (pygame-ce) and ``"web"`` the ``viewer`` extra (websockets): a mode
    whose package cannot be found is left out, since PettingZoo's ``render_test`` starts every listed mode. The
    package is looked up, not imported. ``render_mode`` still takes every mode of ``RENDER_MODES``; one whose
    extra is missing fails on the first ``reset`` with the install command.
    """
    return [m for m in RENDER_MODES if m not in _MODE_NEEDS or _findable(_MODE_NEEDS[m])]


def _findable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a blocked import (None in sys.modules, a refusing finder)
        return False


def _checked(part: np.ndarray | None) -> np.ndarray:
    """``part``, or ``ValueError`` when :func:`scatter_part` found a NaN or inf (the caller finds the agent)."""
    if part is None:
        raise ValueError
    return part


class AgentSimParallelEnv(MessageCalls, ParallelEnv):
    """A PettingZoo ``ParallelEnv`` over one world of a scenario.

    Args:
        scenario: The scenario (with its validated config).
        render_mode: ``None``, ``"rgb_array"`` (``render()`` returns a frame), ``"human"`` (a live pygame-ce
            window, updated on every step) or ``"web"`` (the 3D browser viewer: the first ``reset`` starts a local
            server and prints its URL, ``env.viewer.url``; every step streams to the page; docs/viewer.md).
        obs_format: ``"dict"`` (a Dict of the scenario's observation parts) or ``"flat"`` (one float32 Box).
        action_format: ``"dict"`` (a Dict of action parts) or ``"flat"`` (one float32 Box in [-1, 1]).
        check_finite: Debug switch: after every reset and step, raise ``FloatingPointError`` naming the part and
            the agent when an observation, reward or info handed out is NaN or inf (``None``: on when the
            environment variable ``AGENTSIM_CHECK_FINITE`` is ``1``; the test suite sets it).
        num_threads: Threads for the per-agent kernels, 1..256 (default 1). Worth it from tens of thousands of
            agents; results are identical for every count (``core.threads``).
        ended_agents: ``"leave"`` (default, PettingZoo's rule): an agent that terminates or truncates leaves
            ``agents`` and the dicts ``step`` returns. ``"stay"``: it stays in ``agents`` and in every dict until
            the episode ends, observing zeros, with reward 0, neutral infos (each key at 0) and the terminated /
            truncated flags it ended with; its actions are accepted and ignored. The episode ends (``agents``
            empty) in the step where the last live agent ends, at the latest at ``max_steps``. For clients that
            need a fixed set of agents (SuperSuit's ``MarkovVectorEnv`` without ``black_death``, AgileRL, skrl).

    Attributes:
        observation_spaces: ``{agent: space}`` for every possible agent, the objects ``observation_space``
            returns (one shared object).
        action_spaces: ``{agent: space}``, likewise for ``action_space``.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        render_mode: str | None = None,
        obs_format: str = "dict",
        action_format: str = "dict",
        check_finite: bool | None = None,
        num_threads: int = 1,
        ended_agents: str = "leave",
    ) -> None:
        if render_mode is not None:
            check_choice("render_mode", render_mode, RENDER_MODES + (None,))
        check_choice("obs_format", obs_format, FORMATS)
        check_choice("action_format", action_format, FORMATS)
        check_choice("ended_agents", ended_agents, ENDED_AGENTS)
        num_threads = check_num_threads(num_threads)
        self.scenario = scenario
        self.check_finite = check_finite_default(check_finite)
        self.render_mode = render_mode
        self.obs_format = obs_format
        self.action_format = action_format
        self.ended_agents = ended_agents
        self._stay = ended_agents == "stay"
        self.world = scenario.build(1)
        self.world.set_num_threads(num_threads)
        self.metadata: dict[str, Any] = {
            "name": f"{scenario.name}_v{scenario.version}",
            "render_modes": available_render_modes(),
            "render_fps": max(1, int(round(1.0 / self.world.config.dt))),
            "is_parallelizable": True,
        }
        self.possible_agents = scenario.agent_names()
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        # every agent has the same spaces: one object each, shared (200,000 agents would otherwise build
        # 400,000 gymnasium spaces, seconds of work for nothing)
        obs_parts = scenario.obs_parts()
        obs_space = observation_space_for(obs_parts, obs_format)
        self._obs_keys = tuple(obs_parts)
        self._obs_cols = [(sl, obs_parts[k].shape) for k, sl in flat_layout(obs_parts).items()]
        self._obs_out = Recycled((self.world.state.n_slots, sum(p.size for p in obs_parts.values())), np.float32)
        self._act_parts = scenario.act_parts()  # fixed per config; read on every step
        act_space = action_space_for(self._act_parts, action_format)
        # public, as PettingZoo's ParallelEnv declares them (skrl reads them); observation_space(a) is a lookup here
        self.observation_spaces = dict.fromkeys(self.possible_agents, obs_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, act_space)
        n = scenario.state_size()
        self.state_space = spaces.Box(-10.0, 10.0, shape=(n,), dtype=np.float32)
        self.agents: list[str] = []
        self._set_agents([])
        # "stay": the flags each agent ended with, reported until the episode ends
        self._terminated = np.zeros(self.world.state.n_slots, dtype=bool)
        self._truncated = np.zeros(self.world.state.n_slots, dtype=bool)
        self._info_keys = scenario.info_keys()
        self._seeds = EpisodeSeeds()  # fresh entropy until a reset gives a seed
        self._steps = 0
        self._started = False
        self._window: Any = None
        self.viewer: Any = None  # the web viewer (render_mode="web"), started by the first reset
        self._guard = CallGuard()  # reset, step, close and the message calls: one thread at a time

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent``: one object shared by every agent (seeding it seeds all)."""
        return self.observation_spaces[self._check_known(agent)]

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent``: one object shared by every agent (seeding it seeds all)."""
        return self.action_spaces[self._check_known(agent)]

    def _check_known(self, agent: str) -> str:
        if agent not in self._index:
            raise ValueError(
                f"unknown agent id {agent!r}; agents are {self.possible_agents[0]!r}...{self.possible_agents[-1]!r}"
            )
        return agent

    # ------------------------------------------------------------------ episode
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Start an episode; ``seed`` re-seeds the env's generator (otherwise it continues).

        Raises:
            RuntimeError: Another thread is inside a call of this env (``step``, ``reset``, ``close``...).
        """
        self._guard.enter("reset")
        try:
            return self._reset(seed)
        finally:
            self._guard.exit()

    def _reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        flat = self._begin(seed)
        infos = self._reset_infos()
        return self._obs_dicts(flat, self._live, self._live_idx), infos

    def _begin(self, seed: int | None) -> np.ndarray:
        """Start an episode (``reset`` without its dicts): the flat observations of every slot."""
        if seed is not None:
            self._seeds.reset(seed)
        self._reset_core(self._seeds.next())
        self._steps = 0
        self._started = True
        self._set_agents(list(self.possible_agents))
        if self._stay:
            self.agents = list(self.possible_agents)
            self._terminated[:] = False
            self._truncated[:] = False
        flat = self._flat_obs(self.world.state.online)
        if self.render_mode == "human":
            self.render()
        elif self.render_mode == "web":
            self._web_episode()
        return flat

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance one step with an action for every live agent (see the scenario docstring for layouts).

        Actions for agents that ended earlier in the episode are ignored (``ended_agents="stay"`` keeps them in
        ``agents``, so clients send them).

        Raises:
            ValueError: A bad action (the message names the agent and the part) or no episode running.
            RuntimeError: Another thread is inside a call of this env (``step``, ``reset``, ``close``...).
        """
        self._guard.enter("step")
        try:
            return self._step(actions)
        finally:
            self._guard.exit()

    def _step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if not self.agents:
            if not self._started:
                raise ValueError("call reset() before step(): no episode has started")
            if actions:
                raise ValueError(
                    f"the episode is over (no live agents); got actions for {sorted(actions)[:3]}; call reset()"
                )
            return {}, {}, {}, {}, {}
        sc, world = self.scenario, self.world
        # 1. validate everything before any state changes, then decode actions into motion commands
        parts = self._validate_actions(actions)
        acting = self._acting.copy()
        # 1. decode; 2-8. the world pipeline; 9. the scenario scores
        res, terminated = self._step_core(parts, acting)
        self._steps += 1
        over = self._steps >= sc.max_steps
        truncated = acting & ~terminated if over else np.zeros(acting.shape[0], dtype=bool)
        flat = self._flat_obs(acting, res)
        live = self._live
        ended_t, ended_u = bool(terminated.any()), over and bool(truncated.any())
        if self._stay:
            flat[~acting] = 0.0  # agents that ended earlier observe zeros (a fresh array of this step's)
            obs = self._obs_dicts(flat, self.agents, None)
            self._terminated |= terminated
            self._truncated |= truncated
            rewards, terms, truncs, infos = stay_dicts(
                self.agents, acting, res.rewards, self._terminated, self._truncated, res.info
            )
        else:
            obs = self._obs_dicts(flat, live, self._live_idx)
            idx = None if len(live) == world.state.n_slots else self._live_idx  # None: every slot is live
            rewards = dict(zip(live, rows(np.asarray(res.rewards, dtype=np.float64), idx)))
            # terminated and truncated are False outside the live slots: a dict of False is copied when none ended
            terms = dict(zip(live, rows(terminated, idx))) if ended_t else self._all_false.copy()
            truncs = dict(zip(live, rows(truncated, idx))) if ended_u else self._all_false.copy()
            keys = tuple(res.info)
            infos = per_agent(live, keys, [rows(res.info[k], idx) for k in keys]) if keys else {a: {} for a in live}
        if ended_t or ended_u:
            keep = ~(terminated | truncated)[self._live_idx]
            self._set_agents([a for a, k in zip(live, keep.tolist()) if k], self._live_idx[keep])
            if self._stay and not self._live:
                self.agents = []  # the last live agents ended: so does the episode
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    def rollout(
        self, policy: Any, steps: int, seed: int | None = None, *, on_step: RolloutCallback | None = None
    ) -> RolloutResult:
        """Run ``policy`` for up to ``steps`` steps from ``reset(seed=seed)`` on arrays, without per-agent dicts.

        The results (returns, final positions, events) are those of stepping through ``step()`` with the same
        policy; no frames are rendered. ``policy``: a baseline name registered for the scenario, a trained model
        folder or ``.zip``, a dict ``Policy`` (the slow path) or an ``ArrayPolicy``; ``on_step(env, steps so far,
        view)`` runs after the reset (0) and every step (True stops). ``agentsim_env.env.rollout`` has the rest.

        Raises:
            ValueError: A bad ``policy``, ``steps`` or ``seed`` (the message names it and what is allowed).
        """
        cls = type(self)  # a front end that overrides reset or step (recording) is exact only through them
        through = cls.reset is not AgentSimParallelEnv.reset or cls.step is not AgentSimParallelEnv.step
        return run_rollout(self, policy, steps, seed, on_step=on_step, through_step=through)

    def _reset_core(self, seed: np.random.SeedSequence) -> None:
        """Start the episode of ``seed`` in the world (the distributed env runs it over its shards)."""
        reset_worlds(self.scenario, self.world, [0], [seed])

    def _step_core(self, parts: dict[str, np.ndarray], acting: np.ndarray) -> tuple[Any, np.ndarray]:
        """Stages 1-10 for validated action parts (the distributed env runs them over its shards)."""
        return run_step(self.scenario, self.world, parts, acting)

    def _set_agents(self, agents: list[str], idx: np.ndarray | None = None) -> None:
        """Set the live agents and the lookups derived from them (rebuilt only when the list changes).

        ``idx``: their slots, when the caller has them. With ``ended_agents="leave"`` the live agents are
        ``agents``; with ``"stay"``, ``agents`` keeps every agent of the episode while it runs.
        """
        self._live = agents
        if not self._stay:
            self.agents = agents
        if idx is None:
            idx = np.fromiter((self._index[a] for a in agents), dtype=np.int64, count=len(agents))
        self._live_idx = idx
        self._acting = np.zeros(self.world.state.n_slots, dtype=bool)
        self._acting[idx] = True
        self._getter = operator.itemgetter(*agents) if len(agents) > 1 else None
        self._all_false = dict.fromkeys(agents, False)

    def _validate_actions(self, actions: dict[str, Any]) -> dict[str, np.ndarray]:
        """Stack the actions of live agents into per-part arrays over slots (validated, clipped).

        The fast path gathers each part for all agents at once; only when something is wrong does the slow
        path check agent by agent, so the error names the agent and the part.
        """
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict agent id -> action, got {type(actions).__name__}")
        live = self._live
        if actions.keys() != self._all_false.keys():
            for a in actions:
                if a not in self._index:
                    raise ValueError(
                        f"unknown agent id {a!r} in actions; agents are {self.possible_agents[0]!r}..."
                        f"{self.possible_agents[-1]!r}"
                    )
            missing = [a for a in live if a not in actions]
            if missing:
                raise ValueError(f"missing actions for live agent(s) {missing[:5]}")
            # actions for agents that ended earlier in this episode (TorchRL, BenchMARL send them): ignored
            actions = {a: actions[a] for a in live}
        parts = self._act_parts
        idx = self._live_idx
        n = len(live)
        acts = self._getter(actions) if self._getter is not None else (actions[live[0]],)
        s = self.world.state.n_slots
        out: dict[str, np.ndarray] = {}
        try:
            # one rule (env.spaces.ACTION_RULE), per agent: real numbers of exactly the part's shape
            if self.action_format == "flat":
                total = sum(p.size for p in parts.values())
                arr = stack_rows(acts)
                if arr.shape != (n, total):
                    raise ValueError
                start = 0
                for name, p in parts.items():
                    out[name] = _checked(scatter_part(arr[:, start : start + p.size], idx, s, p.low, p.high))
                    start += p.size
            else:
                if set(map(len, acts)) != {len(parts)}:
                    raise ValueError
                for name, p in parts.items():
                    arr = stack_rows(list(map(operator.itemgetter(name), acts)))
                    if arr.shape != (n, *p.shape):
                        raise ValueError
                    out[name] = _checked(scatter_part(arr.reshape(n, p.size), idx, s, p.low, p.high))
        except (ValueError, TypeError, KeyError, RuntimeError):
            for a in live:  # slow path: find the culprit and raise naming it
                split_action(actions[a], parts, self.action_format, a)
            raise ValueError("actions could not be stacked; check that every action has the same layout") from None
        return out

    def _reset_infos(self) -> dict[str, dict[str, Any]]:
        """Infos at reset: the keys ``step`` returns, each at its neutral value (0)."""
        return {a: dict.fromkeys(self._info_keys, 0) for a in self._live}

    def _flat_obs(self, rows: np.ndarray, result: Any = None) -> np.ndarray:
        """Flat observations ``(S, obs_dim)`` of every slot (a fresh array); with ``check_finite``, ``rows`` (and
        ``result``) are checked first."""
        out = self._obs_out.get()
        if self.check_finite:
            parts = self.scenario.observation(self.world)
            assert_finite(self.scenario, rows, self._steps, parts, result)
            return flat_parts(parts, self.world.state.n_slots, out, self.world.threads)
        return self.scenario.flat_observation(self.world, out)

    def _obs_dicts(self, flat: np.ndarray, agents: list[str], idx: np.ndarray | None) -> dict[str, Any]:
        """Per-agent observations of ``agents`` (in slots ``idx``; None: every slot) from the fresh flat array:
        rows of it (``"flat"``) or dicts of views of its part columns (``"dict"``); a later step never writes
        into them."""
        if idx is not None and len(agents) != flat.shape[0]:
            flat = flat[idx]
        if self.obs_format == "flat":
            return dict(zip(agents, flat))
        n = flat.shape[0]
        cols = [list(flat[:, sl].reshape(n, *shape)) for sl, shape in self._obs_cols]
        return per_agent(agents, self._obs_keys, cols)

    def state(self) -> np.ndarray:
        """Global state of the world for centralised critics (see ``state_space``)."""
        return self.scenario.state(self.world, 0)

    def _web_episode(self) -> None:
        """Start the web viewer on the first reset; tell it every new episode."""
        if self.viewer is None:
            from agentsim_env.render.web.viewer import WebViewer

            self.viewer = WebViewer(title=self.metadata["name"])
            self.viewer.attach(self.world, self.scenario)
        self.viewer.new_episode()

    def render(self) -> np.ndarray | None:
        """A top-down RGB frame (altitude shown as shading); in ``"human"`` mode it is shown and None returned.

        In ``"web"`` mode the page follows every step by itself: ``render()`` returns None. Without a render mode
        it returns None and warns, once per env (as PettingZoo's and Gymnasium's envs do), since a None frame is
        otherwise easy to miss.
        """
        if self.render_mode is None and not getattr(self, "_render_warned", False):
            self._render_warned = True
            from gymnasium import logger

            logger.warn(
                "render() was called without a render mode, so it returns None; build the env with "
                f"render_mode= one of {self.metadata['render_modes']} (e.g. agentsim_env.make(name, "
                "render_mode='rgb_array'))"
            )
        if self.render_mode is None or self.render_mode == "web":
            return None
        from agentsim_env.render.topdown import render_topdown

        frame = render_topdown(self.world, 0, self.scenario.markers(self.world, 0))
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            from agentsim_env.render.window import Window

            self._window = Window(self.metadata["name"], self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self) -> None:
        """Close the live window or stop the web viewer, if any."""
        with self._guard.hold("close"):
            if self.viewer is not None:
                self.viewer.close()
                self.viewer = None
            if self._window is not None:
                self._window.close()
                self._window = None


def to_aec(env: AgentSimParallelEnv, *, raw: bool = False) -> Any:
    """The AEC version of a parallel env (PettingZoo's ``parallel_to_aec``).

    Args:
        env: The parallel env.
        raw: Without PettingZoo's order checks (its ``parallel_to_aec_wrapper`` alone), as a ``raw_env``.

    Returns:
        The AEC env.

    Raises:
        ValueError: ``env`` was built with ``ended_agents="stay"``: in the AEC API an agent that ended takes one
            ``None`` action and leaves, so it cannot stay listed.
    """
    if env.ended_agents != "leave":
        raise ValueError(
            f"ended_agents must be 'leave' for the AEC API (an agent that ended steps once with None and leaves), "
            f"got {env.ended_agents!r}; ended_agents='stay' is for parallel clients"
        )
    return parallel_to_aec_wrapper(env) if raw else parallel_to_aec(env)


#: The keys of ``build_parallel_env`` (and ``agentsim_env.make``) that configure the env, not the scenario.
ENV_KEYS = ("render_mode", "obs_format", "action_format", "check_finite", "num_threads", "ended_agents")


def build_parallel_env(name: str, defaults: dict[str, Any] | None = None, **config: Any) -> AgentSimParallelEnv:
    """The ParallelEnv of scenario ``name`` (what ``agentsim_env.make`` returns; the adapters build through it).

    Args:
        name: A registered scenario.
        defaults: Env keys (``ENV_KEYS``) used when ``config`` does not give them (an adapter's formats).
        **config: Env keys and the scenario's config fields (unknown keys raise ``ValueError`` naming them).

    Returns:
        The env.
    """
    env_kw = dict(defaults or {})
    env_kw.update({k: config.pop(k) for k in ENV_KEYS if k in config})
    return AgentSimParallelEnv(make_scenario(name, **config), **env_kw)
