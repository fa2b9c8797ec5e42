"""``agentsim train`` (also ``python -m agentsim_env.train``): train, checkpoint, evaluate against the baselines.

The run folder (``--out``, default ``outputs/train/<scenario>``) receives the model, its config, the learning
curve (CSV + PNG), checkpoints, TensorBoard logs and the evaluation table (``eval.csv``, ``eval.md``); see
``agentsim_env.train.runner`` for the files.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from agentsim_env.cli_set import parse_set
from agentsim_env.outdirs import prepare_out, remove_created

__all__ = ["add_train_command", "cmd_train", "main", "parse_overrides"]

EPILOG = """\
Shipped configs (--config NAME or a YAML path; the scenario's own is the default): {configs}
--set takes training keys (timesteps=2e6 is not an int: write 2000000), ppo.* and eval.* keys, and env.* keys
for the scenario config (env.n_agents=8, env.comms.loss=0.5).

examples:
  agentsim train navigation                                  # train/configs/navigation.yaml
  agentsim train navigation --timesteps 200000 --out outputs/train/nav_small
  agentsim train uav_release --timesteps 20000 --eval-baselines default   # evaluate beside B5_cvt only
  agentsim train relay --config relay_nocomm --set seed=1 ppo.learning_rate=0.0001
  agentsim train relay --config relay_curriculum --out outputs/train/relay_cur   # stage by stage (curriculum:)
  agentsim train relay --config relay_curriculum --out outputs/train/relay_cur --resume --timesteps 80000000
  agentsim train navigation --out outputs/train/nav --resume  # continue from the newest checkpoint that loads
  agentsim train navigation --out outputs/train/nav --eval-only --record eval.db
  agentsim run navigation --policy outputs/train/navigation    # the trained model beside the baselines"""


def parse_overrides(scenario: str, pairs: list[str]) -> dict[str, Any]:
    """``--set`` pairs as config overrides: ``env.*`` keys typed by the scenario's config, the rest by
    ``TrainConfig``'s fields (``ppo.*``, ``eval.*`` dotted)."""
    from agentsim_env.scenarios.registry import scenario_class
    from agentsim_env.train.config import TrainConfig

    env_pairs = [p[4:] for p in pairs if p.startswith("env.")]
    rest = [p for p in pairs if not p.startswith("env.")]
    out = parse_set(TrainConfig, rest)
    if env_pairs:
        out["env"] = {**out.get("env", {}), **parse_set(scenario_class(scenario).config_cls, env_pairs)}
    return out


def add_train_command(sub: Any) -> argparse.ArgumentParser:
    """Add ``train`` to the ``agentsim`` subcommands (``sub`` is the parser's subparsers object)."""
    t = sub.add_parser(
        "train",
        help="train a PPO policy (parameter sharing) and evaluate it against the baselines",
        description="Train PPO with parameter sharing on a scenario from a YAML config; write the "
        "model,\ncheckpoints, TensorBoard logs, the learning curve and the evaluation against every "
        "scripted baseline.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=_epilog(),
    )
    _arguments(t)
    t.set_defaults(func=cmd_train)
    return t


def _epilog() -> str:
    from agentsim_env.train.config import shipped_configs

    return EPILOG.format(configs=", ".join(shipped_configs()) or "-")


def _arguments(t: argparse.ArgumentParser) -> None:
    t.add_argument("scenario", metavar="SCENARIO", help="a registered scenario ('agentsim scenarios')")
    t.add_argument(
        "--config",
        default=None,
        metavar="FILE",
        help="YAML config or shipped config name (default: the scenario's shipped config); a config with a "
        "'curriculum:' section trains one network stage by stage, promoted on an evaluation threshold "
        "(--timesteps is then the total budget over all stages)",
    )
    t.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="config keys over the file's")
    t.add_argument("--timesteps", type=int, default=None, help="agent-steps to train (over the config's)")
    t.add_argument("--seed", type=int, default=None, help="seed of envs and network (over the config's)")
    t.add_argument("--worlds", type=int, default=None, help="worlds stepped together (over the config's)")
    t.add_argument("--vec", choices=["native", "supersuit"], default=None, help="vector-env path")
    t.add_argument("--out", default=None, help="run folder (default outputs/train/SCENARIO)")
    t.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --out from its newest checkpoint that loads (a curriculum: from its state file)",
    )
    t.add_argument("--eval-only", action="store_true", help="evaluate the model in --out, do not train")
    t.add_argument("--no-eval", action="store_true", help="skip the evaluation against the baselines")
    t.add_argument(
        "--eval-baselines",
        choices=["none", "default", "all"],
        default=None,
        help="baselines the evaluation plays beside the model: none, the scenario's default one, or all "
        "(over the config's eval.baselines; all can take far longer than a short training run)",
    )
    t.add_argument(
        "--record",
        default=None,
        metavar="PATH",
        help="record the evaluation episodes to this SQLite store (one run per policy)",
    )
    t.add_argument(
        "--record-training",
        default=None,
        metavar="PATH",
        help="record the training env (every world and step) to this SQLite store",
    )
    t.add_argument("--quiet", action="store_true", help="no progress bars")


def _load(args: argparse.Namespace) -> Any:
    """The ``TrainConfig``, or the ``Curriculum`` of a config with a ``curriculum:`` section."""
    from agentsim_env.train.config import load_config
    from agentsim_env.train.curriculum import has_curriculum, load_curriculum

    overrides = parse_overrides(args.scenario, args.set or [])
    for key in ("timesteps", "seed", "worlds", "vec"):
        if getattr(args, key) is not None:
            overrides[key] = getattr(args, key)
    if getattr(args, "eval_baselines", None) is not None:
        overrides["eval"] = {**overrides.get("eval", {}), "baselines": args.eval_baselines}
    if args.config is not None and has_curriculum(args.config, args.scenario):
        return load_curriculum(args.config, overrides, scenario=args.scenario)
    return load_config(args.config, overrides, scenario=args.scenario)


def cmd_train(args: argparse.Namespace) -> int:
    """Run ``agentsim train``; see the module docstring."""
    from agentsim_env.scenarios.registry import scenario_class

    scenario_class(args.scenario)  # an unknown scenario is named before anything else
    from agentsim_env.train.curriculum import STATE_FILE, Curriculum

    cfg = _load(args)
    curriculum = isinstance(cfg, Curriculum)
    if args.resume and args.eval_only:
        raise ValueError("give --resume or --eval-only, not both")
    if curriculum and args.record_training:
        raise ValueError("--record-training is not available with a curriculum config")
    out = Path(args.out or f"outputs/train/{args.scenario}")
    if curriculum:
        has_run = (out / STATE_FILE).exists()
    else:
        has_run = (out / "model.zip").exists() or any((out / "checkpoints").glob("*.zip"))
    if args.eval_only and not (out / "model.zip").exists():
        raise ValueError(f"--eval-only: no model.zip in {str(out)!r}")
    if has_run and not (args.resume or args.eval_only):
        raise ValueError(
            f"--out {str(out)!r} already holds a {'curriculum ' if curriculum else ''}run: pass --resume to "
            "continue it, --eval-only to evaluate it, or choose another --out"
        )
    for option, value in (("--record", args.record), ("--record-training", args.record_training)):
        if value:
            from agentsim_env.recorder.schema import StoreError, check_store_path

            try:
                check_store_path(value)
            except StoreError as exc:
                raise ValueError(f"{option} {exc}") from None
    created = prepare_out(out)
    try:
        return (_curriculum_and_report if curriculum else _train_and_report)(args, cfg, out)
    except BaseException:
        remove_created(created)
        raise


def _train_and_report(args: argparse.Namespace, cfg: Any, out: Path) -> int:
    from agentsim_env.train.callbacks import read_curve
    from agentsim_env.train.evaluate import evaluate_policies, format_table, write_table
    from agentsim_env.train.plots import plot_learning_curve

    progress = not args.quiet
    if args.eval_only:
        model: Any = out
        curve = read_curve(out / "curve.csv") if (out / "curve.csv").exists() else []
        summary = f"model {out / 'model.zip'}"
    else:
        from agentsim_env.train.runner import train

        res = train(cfg, out, resume=args.resume, progress=progress, record=args.record_training)
        model, curve = res.model, res.curve
        summary = (
            f"trained {res.timesteps:,} agent-steps in {res.wall_s:.0f} s wall / {res.cpu_s:.0f} s CPU "
            f"-> {out / 'model.zip'}"
        )
    print(f"\n{cfg.scenario}: {summary}")
    rows: list[dict[str, Any]] = []
    if not args.no_eval:
        from tqdm.auto import tqdm

        # the cost lines go through tqdm so that they do not break its progress bar
        rows = evaluate_policies(
            cfg,
            model,
            name=out.name,
            record=args.record,
            progress=progress,
            report=lambda line: tqdm.write(line, file=sys.stdout),
        )
        csv_path, md_path = write_table(rows, out)
        seeds = cfg.eval.seed_list()
        print(f"\nevaluation over seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} episodes per policy):\n")
        print(format_table(rows))
        print(f"\nwritten: {csv_path}, {md_path}")
    if curve:
        png = plot_learning_curve(
            curve,
            out / "curve.png",
            eval_rows=rows,
            title=f"{cfg.scenario}: PPO, {cfg.worlds} worlds, seed {cfg.seed}",
        )
        print(f"learning curve: {png} (CSV: {out / 'curve.csv'}; TensorBoard: tensorboard --logdir {out / 'tb'})")
    if args.record:
        print(f"evaluation episodes recorded to {args.record}")
    return 0


def _curriculum_and_report(args: argparse.Namespace, cur: Any, out: Path) -> int:
    """``agentsim train`` with a curriculum config: train stage by stage, then evaluate the newest model at the
    stage reached and at the last stage (the target), beside the baselines there."""
    from tqdm.auto import tqdm

    from agentsim_env.train.curriculum import STATE_FILE, read_state, run_curriculum
    from agentsim_env.train.evaluate import evaluate_policies, format_table, write_table

    say = lambda line: tqdm.write(line, file=sys.stdout)  # noqa: E731  (lines between the progress bars)
    if args.eval_only:
        state = read_state(out)
    else:
        state = run_curriculum(cur, out, resume=args.resume, progress=not args.quiet, say=say)
    k, last = int(state["stage"]), len(cur.stages) - 1
    names = [s.name for s in cur.spec.stages]
    print(
        f"\n{cur.base.scenario} curriculum: stage {k + 1}/{last + 1} ({names[k]}) reached, "
        f"{state['finished'] or 'not finished'}; {int(state['timesteps']):,} agent-steps in "
        f"{state['wall_s']:.0f} s wall / {state['cpu_s']:.0f} s CPU -> {out / 'model.zip'}"
    )
    if not args.no_eval:
        rows = []
        for j in sorted({k, last}):
            cfg = cur.stages[j] if j == last else cur.stages[j].replace(eval={"baselines": "none"})
            got = evaluate_policies(
                cfg, out, name=f"{out.name}@{names[j]}", record=args.record, progress=not args.quiet, report=say
            )
            rows += [{"stage": names[j], **r} for r in got]
        csv_path, md_path = write_table(rows, out)
        seeds = cur.base.eval.seed_list()
        print(f"\nevaluation over seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} episodes per policy):\n")
        print(format_table(rows))
        print(f"\nwritten: {csv_path}, {md_path}")
    if (out / "curriculum.png").exists():
        print(f"curriculum curve: {out / 'curriculum.png'} (CSV: {out / 'curriculum.csv'}; state: {out / STATE_FILE})")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m agentsim_env.train``: the same command as ``agentsim train``."""
    p = argparse.ArgumentParser(
        prog="python -m agentsim_env.train",
        epilog=_epilog(),
        description=__doc__.splitlines()[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _arguments(p)
    args = p.parse_args(argv)
    try:
        return cmd_train(args)
    except ValueError as exc:
        print(f"agentsim train: error: {exc}", file=sys.stderr)
        return 2
