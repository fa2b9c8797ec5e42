"""PPO training throughput on ``navigation``: the native SB3 VecEnv (``AgentSimVecEnv``) vs the SuperSuit path.

Both paths give SB3 one entry per agent (parameter sharing): the native one steps W worlds of 4 agents in one
``BatchedEnv`` call, the SuperSuit one (``agentsim_env.env.supersuit.supersuit_vec_env``) steps W copies of the
4-agent ParallelEnv one after the other through ``black_death`` -> ``pettingzoo_env_to_vec_env_v1`` ->
``concat_vec_envs_v1``. Slots = W x 4 entries. Every measurement trains a fresh PPO with the hyperparameters of a
training config (``--ppo shipped``, the default: ``train/configs/navigation.yaml``, built by the training runner's
``make_model``; ``--ppo small``: SB3 defaults except ``n_steps=64``, ``batch_size=512``, ``n_epochs=10``; seed =
the round) for ``--timesteps`` agent-steps with one thread; the learn() call is timed end to end (process CPU time). A
thin
``VecEnvWrapper`` times the env's ``reset`` and ``step_wait`` and the model's ``train`` is timed too, which
gives the env's and the PPO update's shares of the learn() time. Rounds are interleaved (each round trains
every system at every size in turn) and the table shows medians over rounds; the ratio is of the medians.
``ratio ceiling`` is what the native/SuperSuit ratio would be if the native env cost nothing (SuperSuit learn
time over native learn time minus its env time); ``rollout ratio`` compares the rollout phase alone (learn time
minus update time, per agent-step), the part of PPO that the env's speed can change. Env-only rows step each vec env
with random actions (a pool of
16, cycled) through ``common.measure_interleaved``, counting every entry as one agent-step.

Run: ``.venv/bin/python benchmarks/bench_train.py [--quick] [--rounds 3] [--slots 16 64] [--timesteps N]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import argparse  # noqa: E402
import itertools  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from typing import Any  # noqa: E402

import common  # noqa: E402  (pins thread pools before numpy / numba / torch load)
import numpy as np  # noqa: E402

SCENARIO = "navigation"
AGENTS = 4  # agents per world / per ParallelEnv copy
SLOTS = (16, 64)
SYSTEMS = ("native", "supersuit")
PPO_KW: dict[str, Any] = {"n_steps": 64, "batch_size": 512, "n_epochs": 10, "device": "cpu"}
TARGET_SLOTS = 64
TARGET_RATIO = 3.0  # native >= 3x SuperSuit end to end at 64 slots
POOL = 16


def make_vec(system: str, slots: int, seed: int) -> Any:
    """The vec env of ``system`` with ``slots`` entries (``slots / AGENTS`` worlds or copies)."""
    worlds = slots // AGENTS
    if system == "native":
        from agentsim_env.env.sb3 import AgentSimVecEnv

        return AgentSimVecEnv(SCENARIO, worlds, seed=seed, n_agents=AGENTS)
    from agentsim_env.env.supersuit import supersuit_vec_env

    return supersuit_vec_env(SCENARIO, worlds, seed=seed, n_agents=AGENTS)


def timed_vec_env(venv: Any) -> Any:
    """``venv`` under a ``VecEnvWrapper`` that sums the CPU seconds spent in its ``reset`` and ``step_wait``."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class Timed(VecEnvWrapper):
        env_s = 0.0

        def reset(self) -> Any:
            t0 = time.process_time()
            obs = self.venv.reset()
            self.env_s += time.process_time() - t0
            return obs

        def step_wait(self) -> Any:
            t0 = time.process_time()
            out = self.venv.step_wait()
            self.env_s += time.process_time() - t0
            return out

    return Timed(venv)


@dataclass
class LearnRun:
    """One timed ``learn()`` call.

    Attributes:
        steps: Agent-steps trained (whole rollouts: at least the budget).
        cpu_s: CPU seconds of the call.
        wall_s: Wall seconds of the call.
        env_s: CPU seconds inside the vec env (reset and step_wait).
        train_s: CPU seconds inside the PPO update (``train``).
    """

    steps: int
    cpu_s: float
    wall_s: float
    env_s: float
    train_s: float


def ppo_config(kind: str) -> Any:
    """The training config whose PPO settings the benchmark uses: ``shipped`` (navigation.yaml) or ``small``."""
    from agentsim_env.train.config import load_config

    cfg = load_config("navigation", {"env": {"n_agents": AGENTS}})
    if kind == "small":
        cfg = cfg.replace(
            ppo={k: PPO_KW[k] for k in ("n_steps", "batch_size", "n_epochs")}
            | {"learning_rate": 3e-4, "gamma": 0.99, "net_arch": [64, 64], "lr_schedule": "constant"}
        )
    return cfg


def learn_once(system: str, slots: int, timesteps: int, seed: int, kind: str = "shipped") -> LearnRun:
    """Train a fresh PPO for ``timesteps`` agent-steps and time it."""
    from agentsim_env.train.runner import make_model

    venv = timed_vec_env(make_vec(system, slots, seed))
    model = make_model(ppo_config(kind).replace(seed=seed), venv)
    update = model.train
    spent = [0.0]

    def timed_train() -> None:
        t0 = time.process_time()
        update()
        spent[0] += time.process_time() - t0

    model.train = timed_train  # type: ignore[method-assign]  # learn() calls self.train() once per rollout
    c0, w0 = time.process_time(), time.perf_counter()
    model.learn(timesteps)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    venv.close()
    return LearnRun(int(model.num_timesteps), max(cpu, 1e-9), wall, venv.env_s, spent[0])


@dataclass
class Summary:
    """Medians over rounds of one system at one size.

    Attributes:
        rate: Agent-steps per CPU second of learn().
        wall_rate: Agent-steps per wall second of learn().
        env_share: Share of learn()'s CPU time inside the vec env.
        train_share: Share of learn()'s CPU time inside the PPO update.
        learn_s: CPU seconds of one learn() call.
        env_s: CPU seconds inside the vec env in one learn() call.
        rollout_s_per_step: CPU seconds per agent-step outside the update (rollout collection).
        runs: The timed calls.
    """

    rate: float
    wall_rate: float
    env_share: float
    train_share: float
    learn_s: float
    env_s: float
    rollout_s_per_step: float
    runs: list[LearnRun] = field(default_factory=list)


def summarise(runs: list[LearnRun]) -> Summary:
    """Medians of the per-round numbers."""
    med = lambda f: float(np.median([f(r) for r in runs]))  # noqa: E731
    return Summary(
        med(lambda r: r.steps / r.cpu_s),
        med(lambda r: r.steps / r.wall_s),
        med(lambda r: r.env_s / r.cpu_s),
        med(lambda r: r.train_s / r.cpu_s),
        med(lambda r: r.cpu_s),
        med(lambda r: r.env_s),
        med(lambda r: (r.cpu_s - r.train_s) / r.steps),
        runs,
    )


def env_case(system: str, slots: int, seed: int) -> common.Case:
    """Raw stepping of one vec env with random actions; every entry counts as one agent-step."""
    venv = make_vec(system, slots, seed)
    venv.reset()
    rng = np.random.default_rng(seed)
    space = venv.action_space
    nxt: Callable[[], np.ndarray] = itertools.cycle(
        [rng.uniform(-1, 1, (slots, *space.shape)).astype(np.float32) for _ in range(POOL)]
    ).__next__

    def step() -> int:
        venv.step(nxt())
        return slots

    return common.Case(step)


def machine_lines() -> list[str]:
    """The machine line of ``common`` plus the RL packages and the date."""
    from importlib import metadata

    def ver(p: str) -> str:
        try:
            return metadata.version(p)
        except metadata.PackageNotFoundError:
            return "-"

    pkgs = ", ".join(f"{p} {ver(p)}" for p in ("stable-baselines3", "supersuit", "pettingzoo", "gymnasium"))
    date = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return [f"machine: {common.machine_description()}", f"packages: {pkgs}", f"date: {date}"]


def main(argv: list[str] | None = None) -> dict:
    """Measure both paths at every size, print the table, and return the raw results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one rollout per learn() and short env blocks (smoke)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3, quick 1)")
    ap.add_argument("--slots", type=int, nargs="+", default=list(SLOTS), help="entries (multiples of 4)")
    ap.add_argument("--timesteps", type=int, default=None, help="agent-steps per learn() (default 32768)")
    ap.add_argument("--block-s", type=float, default=None, help="seconds per env-only block (default 0.2)")
    ap.add_argument(
        "--ppo",
        choices=["shipped", "small"],
        default="shipped",
        help="PPO settings: the shipped navigation config, or n_steps 64 / batch 512 / 10 epochs",
    )
    args = ap.parse_args(argv)
    for s in args.slots:
        if s < AGENTS or s % AGENTS:
            ap.error(f"--slots must be multiples of {AGENTS}, got {s}")
    rounds = args.rounds or (1 if args.quick else 3)
    block_s = args.block_s if args.block_s is not None else (0.02 if args.quick else 0.2)
    common.torch_single_thread()
    for line in machine_lines():
        print(line)
    p = ppo_config(args.ppo).ppo
    budget = {
        s: args.timesteps or (p.n_steps * s if args.quick else max(65_536, 4 * p.n_steps * s)) for s in args.slots
    }
    print(
        f"mode: {'quick' if args.quick else 'full'}; PPO ({args.ppo}) MlpPolicy n_steps={p.n_steps} "
        f"batch_size={p.batch_size} n_epochs={p.n_epochs} net_arch={list(p.net_arch)} cpu, 1 thread; "
        f"{rounds} interleaved rounds; medians of agent-steps per CPU second",
        flush=True,
    )
    for s in args.slots:  # warm-up (numba compilation, torch's first calls): one rollout each, untimed
        for system in SYSTEMS:
            learn_once(system, s, p.n_steps * s, 0, args.ppo)
    runs: dict[tuple[str, int], list[LearnRun]] = {(k, s): [] for k in SYSTEMS for s in args.slots}
    for r in range(rounds):
        for s in args.slots:
            for system in SYSTEMS:
                runs[(system, s)].append(learn_once(system, s, budget[s], r, args.ppo))
        print(f"  round {r + 1}/{rounds} done", flush=True)
    cases = {f"{k} {s}": env_case(k, s, 0) for s in args.slots for k in SYSTEMS}
    env_stats = common.measure_interleaved(cases, max(rounds, 3), block_s)
    rows, results = [], {}
    for s in args.slots:
        nat, sus = summarise(runs[("native", s)]), summarise(runs[("supersuit", s)])
        ratio = nat.rate / sus.rate
        ceiling = sus.learn_s / max(nat.learn_s - nat.env_s, 1e-9)
        rollout = sus.rollout_s_per_step / max(nat.rollout_s_per_step, 1e-12)
        env_nat, env_sus = env_stats[f"native {s}"], env_stats[f"supersuit {s}"]
        env_ratio = env_nat.agent_steps_per_s / env_sus.agent_steps_per_s
        met = "-" if s != TARGET_SLOTS else ("PASS" if ratio >= TARGET_RATIO else "FAIL")
        results[s] = {
            "native": nat,
            "supersuit": sus,
            "ratio": ratio,
            "ceiling": ceiling,
            "rollout_ratio": rollout,
            "env_ratio": env_ratio,
            "env": {"native": env_nat, "supersuit": env_sus},
            "result": met,
        }
        pct = lambda x: common.fmt_num(100 * x)  # noqa: E731
        rows.append(
            [
                f"{s} ({s // AGENTS}x{AGENTS})",
                common.fmt_num(nat.rate),
                common.fmt_num(sus.rate),
                f"{ratio:.3g}",
                f">= {TARGET_RATIO:g}" if s == TARGET_SLOTS else "-",
                met,
                f"{ceiling:.3g}",
                f"{rollout:.3g}",
                pct(nat.env_share),
                pct(nat.train_share),
                pct(sus.env_share),
                pct(sus.train_share),
                common.fmt_num(env_nat.agent_steps_per_s),
                common.fmt_num(env_sus.agent_steps_per_s),
                f"{env_ratio:.3g}",
            ]
        )
    headers = [
        "slots (WxN)",
        "native learn ag-st/s",
        "SuperSuit learn ag-st/s",
        "native/SuperSuit",
        "target",
        "result",
        "ratio ceiling",
        "rollout ratio",
        "native env %",
        "native update %",
        "SuperSuit env %",
        "SuperSuit update %",
        "native env-only ag-st/s",
        "SuperSuit env-only ag-st/s",
        "env-only ratio",
    ]
    print()
    print(common.markdown_table(headers, rows))
    print()
    print(
        "learn ag-st/s = agent-steps trained per CPU second of PPO.learn(); env % / update % = share of that "
        "time inside the vec env's reset + step_wait / inside PPO's update (train); the rest is rollout-side "
        "policy inference and buffer work. ratio ceiling = native/SuperSuit if the native env cost nothing; "
        "rollout ratio = native/SuperSuit over the rollout phase only (learn() minus the update)."
    )
    return results


if __name__ == "__main__":
    main()
