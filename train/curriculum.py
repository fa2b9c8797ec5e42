"""Curriculum training: one PPO network trained through a list of scenario configs, promoted on success.

A curriculum config is a training config (``agentsim_env.train.config``) with a ``curriculum:`` section::

    scenario: relay
    timesteps: 30000000          # the total budget in agent-steps, over every stage
    env: {...}                   # the base scenario config; each stage's env is merged onto it
    ppo: {...}
    curriculum:
      metric: groups_reached     # evaluation column that promotes: groups_reached | all_groups_reached | ...
      eval_every: 500000         # agent-steps between evaluations (each one a checkpoint)
      eval_seeds: 10             # episodes per evaluation, seeds eval_first_seed ...
      eval_first_seed: 5000      # held out from training and from the final evaluation
      on_stage_budget: advance   # a stage out of budget: advance to the next one anyway, or stop the run
      stages:
        - {name: pair, threshold: 0.8, budget: 6000000, env: {n_groups: 1, group_size: 2}}
        - {name: target, threshold: null, env: {}}   # null: never promoted, trains to the end of the budget

Every stage must give the same observation and action shapes (one network); that is checked at load time.
The run trains in segments of ``eval_every`` agent-steps. Each segment builds the stage's vector env with a seed
drawn from ``(seed, segment)``, loads the previous segment's checkpoint (a fresh network for the first), trains,
writes the checkpoint, evaluates the deterministic policy on the held-out seeds and records the result in the
state file. The stage is promoted when the metric reaches the threshold; the last stage's promotion ends the run.
Because every segment starts from its checkpoint file, a run resumed after an interruption (``resume=True``)
continues exactly as the uninterrupted one (the interrupted segment is trained again).

Files of the run folder ``out``:

=========================  =================================================================================
``curriculum_state.json``  stage, agent-steps, segment, checkpoint, promotions, evaluations (atomic writes)
``curriculum.csv``         one row per evaluation: agent-steps, stage, metric, threshold, event, clocks
``curriculum.png``         the metric against agent-steps, stage boundaries and thresholds marked
``model.zip``              the newest model with its ``config.json`` (loads as a policy)
``stages/<k>_<name>/``     per stage: ``model.zip`` + ``config.json`` + ``config.yaml``, ``checkpoints/``,
                           ``curve.csv`` (mean return per rollout)
=========================  =================================================================================
"""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
import time
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Choice, Int, config
from agentsim_env.train.config import (
    Fraction,
    Steps,
    TrainConfig,
    _check_keys,
    _deep_merge,
    load_config,
    read_config_data,
)

__all__ = [
    "METRICS",
    "STATE_FILE",
    "Curriculum",
    "CurriculumConfig",
    "StageConfig",
    "default_evaluator",
    "fresh_state",
    "has_curriculum",
    "load_curriculum",
    "read_state",
    "record_evaluation",
    "run_curriculum",
    "write_curve",
]

STATE_FILE = "curriculum_state.json"
Metric = Annotated[Literal["groups_reached", "all_groups_reached", "arrived_per_agent"], Choice]
#: Evaluation columns a stage can be promoted on (shares in [0, 1]).
METRICS: tuple[str, ...] = typing.get_args(typing.get_args(Metric)[0])
CSV_FIELDS = ("timesteps", "stage", "stage_name", "value", "threshold", "event", "wall_s", "cpu_s")


@config()
class StageConfig:
    """One stage.

    Attributes:
        name: Letters, digits, ``_`` and ``-``, 1..40 (its folder is ``stages/<k>_<name>``).
        env: Scenario config keys merged onto the base ``env``.
        threshold: Promotion when the metric reaches it, in [0, 1]; ``None``: never (trains to the budget).
        budget: Most agent-steps in this stage, >= 0 (0: only the total budget limits it).
    """

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]{1,40}$")]
    env: dict[str, Any] = field(default_factory=dict)
    threshold: Fraction | None = None
    budget: Steps = 0


@config("curriculum")
class CurriculumConfig:
    """The ``curriculum:`` section (stages are given as a list of mappings of ``StageConfig``'s fields).

    Attributes:
        stages: The stages, easiest first (at least one).
        metric: The evaluation column that promotes, one of ``METRICS``.
        eval_every: Agent-steps between evaluations, >= 1 (rounded up to whole rollouts).
        eval_seeds: Episodes per evaluation, 1..1,000.
        eval_first_seed: Seed of the first evaluation episode, >= 0.
        on_stage_budget: A stage that used its budget unpromoted: ``advance`` to the next or ``stop`` the run.
    """

    stages: tuple[StageConfig, ...] = ()
    metric: Metric = "groups_reached"
    eval_every: Annotated[Steps, Field(ge=1)] = 500_000
    eval_seeds: Annotated[Int, Field(ge=1, le=1000)] = 10
    eval_first_seed: Annotated[Int, Field(ge=0, le=2**63 - 1)] = 5000
    on_stage_budget: Annotated[Literal["advance", "stop"], Choice] = "stop"


@dataclass
class Curriculum:
    """A loaded curriculum: the base training config, the section, and each stage's full training config."""

    base: TrainConfig
    spec: CurriculumConfig
    stages: list[TrainConfig]

    def to_dict(self) -> dict[str, Any]:
        """Plain data: the base config with its ``curriculum`` section (as a config file holds it)."""
        spec = dataclasses.asdict(self.spec)
        spec["stages"] = [dict(s) for s in spec["stages"]]
        return {**self.base.to_dict(), "curriculum": json.loads(json.dumps(spec))}

    def stage_dir(self, out: Path, k: int) -> Path:
        """Folder of stage ``k``."""
        return out / "stages" / f"{k}_{self.spec.stages[k].name}"


def has_curriculum(source: str | Path | dict[str, Any] | None, scenario: str | None = None) -> bool:
    """Whether a config source has a ``curriculum`` section."""
    return "curriculum" in read_config_data(source, scenario)


def load_curriculum(
    source: str | Path | dict[str, Any], overrides: dict[str, Any] | None = None, *, scenario: str | None = None
) -> Curriculum:
    """Load and check a curriculum config (``overrides`` as for ``load_config``; they apply to the base).

    Raises:
        ValueError: A bad key or value (named with its path, ``curriculum.stages[1].threshold``), no stages,
            duplicate stage names, ``ppo.lr_schedule: linear``, or stages whose observation or action shapes
            differ (both stages and the differing part are named).
    """
    data = read_config_data(source, scenario)
    section = data.pop("curriculum", None)
    base = load_config(data, overrides, scenario=scenario)
    _check_keys(CurriculumConfig, section if section is not None else {}, "curriculum.")
    raw = section.get("stages") if isinstance(section, dict) else None
    if not isinstance(raw, list) or not raw:
        raise ValueError("curriculum.stages must be a non-empty list of stages (mappings with name, env, ...)")
    stages = []
    for k, item in enumerate(raw):
        where = f"curriculum.stages[{k}]"
        _check_keys(StageConfig, item, where + ".")
        try:
            stages.append(StageConfig(**item))
        except ValueError as exc:
            raise ValueError(f"{where}.{exc}") from None
    names = [s.name for s in stages]
    if len(set(names)) != len(names):
        raise ValueError(f"curriculum.stages: names must differ, got {names}")
    assert isinstance(section, dict)
    spec = CurriculumConfig(**{**section, "stages": tuple(stages)})
    if base.ppo.lr_schedule != "constant":
        raise ValueError("ppo.lr_schedule must be 'constant' in a curriculum (each segment restarts SB3's schedule)")
    cfgs = []
    for k, st in enumerate(stages):
        try:
            cfgs.append(base.replace(env=_deep_merge(base.env, st.env)))
        except ValueError as exc:
            raise ValueError(f"curriculum.stages[{k}] ({st.name}): {exc}") from None
    _check_shapes(cfgs, names)
    return Curriculum(base, spec, cfgs)


def _check_shapes(cfgs: list[TrainConfig], names: list[str]) -> None:
    """One network for every stage: the flat observation and action parts must be the same."""
    from agentsim_env.scenarios.registry import make_scenario

    first = None
    for k, cfg in enumerate(cfgs):
        sc = make_scenario(cfg.scenario, **dict(cfg.env))
        shapes = {f"observation {n}": p.shape for n, p in sc.obs_parts().items()}
        shapes.update({f"action {n}": p.shape for n, p in sc.act_parts().items()})
        if first is None:
            first = shapes
            continue
        diff = [p for p in sorted(set(first) | set(shapes)) if first.get(p) != shapes.get(p)]
        if diff:
            p = diff[0]
            raise ValueError(
                f"curriculum.stages[{k}] ({names[k]}) changes the shapes the network sees: {p} is "
                f"{shapes.get(p)} there and {first.get(p)} in stage 0 ({names[0]}); every stage needs the same "
                "(for relay: the same comms.inbox_size, payload_dim and sensing rays)"
            )


# ---------------------------------------------------------------------------------------------- state
def fresh_state(cur: Curriculum) -> dict[str, Any]:
    """The state of a run that has not trained yet."""
    return {
        "config": cur.to_dict(),
        "stage": 0,
        "stage_start": 0,
        "timesteps": 0,
        "segment": 0,
        "checkpoint": None,
        "wall_s": 0.0,
        "cpu_s": 0.0,
        "promotions": [],
        "evals": [],
        "finished": None,
    }


def record_evaluation(cur: Curriculum, state: dict[str, Any], value: float) -> str:
    """Record an evaluation of the metric at ``state["timesteps"]`` and apply the promotion rule.

    Returns:
        The event: ``stay``, ``promoted`` (to the next stage), ``completed`` (the last stage's threshold met),
        ``advanced`` (stage budget used, ``on_stage_budget: advance``), ``stalled`` (stage budget used, ``stop``,
        or the last stage's budget used) or ``budget`` (the total budget used). ``state["finished"]`` is set to
        the event when it ends the run.
    """
    spec, k, steps = cur.spec, int(state["stage"]), int(state["timesteps"])
    stage, last = spec.stages[k], k == len(spec.stages) - 1
    event = "stay"
    if stage.threshold is not None and value >= stage.threshold:
        event = "completed" if last else "promoted"
    elif stage.budget and steps - int(state["stage_start"]) >= stage.budget:
        event = "advanced" if spec.on_stage_budget == "advance" and not last else "stalled"
    if event == "stay" and steps >= cur.base.timesteps:
        event = "budget"
    clocks = {"wall_s": round(float(state["wall_s"]), 3), "cpu_s": round(float(state["cpu_s"]), 3)}
    state["evals"].append({"timesteps": steps, "stage": k, "value": float(value), "event": event, **clocks})
    if event in ("promoted", "advanced"):
        state["promotions"].append({"from": k, "to": k + 1, "timesteps": steps, "value": float(value), "how": event})
        state["stage"], state["stage_start"] = k + 1, steps
        if steps >= cur.base.timesteps:
            state["finished"] = "budget"
    elif event != "stay":
        state["finished"] = event
    return event


def read_state(out: Path) -> dict[str, Any]:
    """The state file of a run folder."""
    path = out / STATE_FILE
    if not path.is_file():
        raise ValueError(f"no {STATE_FILE} in {str(out)!r} (not a curriculum run)")
    try:
        state = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{str(path)!r} is not readable JSON: {exc}") from None
    if not isinstance(state, dict) or not isinstance(state.get("config"), dict):
        raise ValueError(f"{str(path)!r} is not a curriculum state")
    return state


def _check_resumable(cur: Curriculum, state: dict[str, Any], out: Path) -> None:
    before, now = dict(state["config"]), cur.to_dict()
    before.pop("timesteps", None)  # the total budget may grow
    now.pop("timesteps")
    if before != now:
        changed = sorted(k for k in set(now) | set(before) if now.get(k) != before.get(k))
        raise ValueError(
            f"--resume: the config differs from the one the run in {str(out)!r} started with in {changed}; "
            "only timesteps may change"
        )


def _segment_seed(seed: int, segment: int) -> int:
    return int(np.random.SeedSequence([seed, segment]).generate_state(1)[0])


def default_evaluator(cur: Curriculum) -> Callable[[TrainConfig, Any], float]:
    """The metric of the deterministic policy over the curriculum's held-out seeds, in ``cfg``'s env."""
    from agentsim_env.train.evaluate import evaluate_policies

    def evaluate(cfg: TrainConfig, model: Any) -> float:
        ev = {"seeds": cur.spec.eval_seeds, "first_seed": cur.spec.eval_first_seed, "baselines": "none"}
        return float(evaluate_policies(cfg.replace(eval=ev), model)[0].get(cur.spec.metric, 0.0))

    return evaluate


# ---------------------------------------------------------------------------------------------- run
def run_curriculum(
    cur: Curriculum,
    out: str | Path,
    *,
    resume: bool = False,
    progress: bool = False,
    evaluate: Callable[[TrainConfig, Any], float] | None = None,
    say: Callable[[str], None] | None = None,
    max_segments: int | None = None,
) -> dict[str, Any]:
    """Train through the stages as the module docstring says; returns the final state.

    Args:
        cur: The curriculum.
        out: Run folder (created).
        resume: Continue the run in ``out`` from its state file and checkpoint (only ``timesteps`` may differ).
        progress: A progress bar per segment.
        evaluate: ``(stage config, model) -> metric`` (default: :func:`default_evaluator`).
        say: Told one line per evaluation and promotion (default: stderr).
        max_segments: Stop after this many segments (an interruption, for tests); the state stays resumable.
    """
    import torch

    from agentsim_env.policies.learned import load_model
    from agentsim_env.train.callbacks import TrainMonitor
    from agentsim_env.train.checkpoints import write_atomic, write_json_atomic
    from agentsim_env.train.config import save_config
    from agentsim_env.train.runner import _curve_upto, make_model, make_vec_env, save_run

    torch.set_num_threads(1)
    path, n = Path(out), len(cur.stages)
    tell = say or (lambda line: print(line, file=sys.stderr))
    evaluate = evaluate or default_evaluator(cur)
    if resume:
        state = read_state(path)
        _check_resumable(cur, state, path)
        state["config"] = cur.to_dict()
        if state["finished"] == "budget" and state["timesteps"] < cur.base.timesteps:
            state["finished"] = None  # a larger budget continues the run
    else:
        if (path / STATE_FILE).exists():
            raise ValueError(f"{str(path)!r} already holds a curriculum run: resume it or choose another folder")
        state = fresh_state(cur)
    path.mkdir(parents=True, exist_ok=True)
    done_segments = 0
    while state["finished"] is None and (max_segments is None or done_segments < max_segments):
        k = int(state["stage"])
        cfg, spec_k, folder = cur.stages[k], cur.spec.stages[k], cur.stage_dir(path, k)
        folder.mkdir(parents=True, exist_ok=True)
        t0, c0 = time.perf_counter(), time.process_time()
        seed = _segment_seed(cfg.seed, int(state["segment"]))
        vec = make_vec_env(cfg.replace(seed=seed))
        if state["checkpoint"] is None:
            model = make_model(cfg, vec)
        else:  # load, not set_env: the stages' env counts differ, and a resumed segment starts the same way
            model = load_model(path / state["checkpoint"], env=vec, device="cpu")
        model.set_random_seed(seed)
        left = cur.base.timesteps - int(model.num_timesteps)
        if spec_k.budget:
            left = min(left, spec_k.budget - (int(model.num_timesteps) - int(state["stage_start"])))
        kept, _ = _curve_upto(folder, int(model.num_timesteps))  # rows an interrupted segment appended
        if kept is not None:
            write_atomic(folder / "curve.csv", lambda tmp, b=kept: tmp.write_bytes(b))
        monitor = TrainMonitor(
            folder,
            progress=progress,
            desc=f"{cfg.scenario} stage {k + 1}/{n} {spec_k.name}",
            start_wall=float(state["wall_s"]),
            start_cpu=float(state["cpu_s"]),
        )
        try:
            model.learn(max(min(cur.spec.eval_every, left), 1), callback=monitor, reset_num_timesteps=False)
        finally:
            vec.close()
        ckpt = monitor.save_checkpoint()
        assert ckpt is not None, f"checkpoint of {folder} not written"
        state["timesteps"], state["segment"] = int(model.num_timesteps), int(state["segment"]) + 1
        value = evaluate(cfg, model)
        state["wall_s"] = float(state["wall_s"]) + time.perf_counter() - t0
        state["cpu_s"] = float(state["cpu_s"]) + time.process_time() - c0
        for where in (folder, path):  # the stage's newest model, and the run's: each loads as a policy
            save_run(model, cfg, where, wall_s=state["wall_s"], cpu_s=state["cpu_s"])
        write_atomic(folder / "config.yaml", lambda tmp, c=cfg: save_config(c, tmp))
        state["checkpoint"] = str(ckpt.relative_to(path))
        event = record_evaluation(cur, state, value)
        write_json_atomic(path / STATE_FILE, state)
        write_curve(cur, state, path / "curriculum.csv")
        thr = "none" if spec_k.threshold is None else f"{spec_k.threshold:g}"
        tell(
            f"stage {k + 1}/{n} {spec_k.name}: {cur.spec.metric} {value:.3f} (threshold {thr}) at "
            f"{state['timesteps']:,} agent-steps, {state['cpu_s']:.0f} s CPU: {event}"
        )
        done_segments += 1
    if state["evals"]:
        from agentsim_env.train.plots import plot_curriculum

        plot_curriculum(cur, state, path / "curriculum.png")
    return state


def write_curve(cur: Curriculum, state: dict[str, Any], path: Path) -> Path:
    """``curriculum.csv`` from the state's evaluations (rewritten whole, atomically)."""
    from agentsim_env.train.checkpoints import write_atomic

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(CSV_FIELDS)
            for e in state["evals"]:
                st = cur.spec.stages[e["stage"]]
                thr = "" if st.threshold is None else st.threshold
                clocks = [e.get("wall_s", ""), e.get("cpu_s", "")]
                w.writerow([e["timesteps"], e["stage"], st.name, f"{e['value']:.6g}", thr, e["event"], *clocks])

    write_atomic(path, write)
    return path
