"""Train PPO with parameter sharing on a scenario, from a ``TrainConfig``; save, checkpoint, resume.

Every agent of every world is one entry of an SB3 ``VecEnv`` (the native ``AgentSimVecEnv`` over the batched
env, or SuperSuit's path with ``vec: supersuit``), so one network is trained on all agents. A run folder holds:

=====================  ===================================================================================
``model.zip``          the trained model (SB3 format; loads as a policy: ``agentsim run --policy DIR``)
``config.json``        scenario, scenario config, the whole training config, versions, budget used
``config.yaml``        the training config, re-runnable with ``agentsim train --config``
``curve.csv``          one row per rollout: agent-steps, episodes, mean return (last 100 episodes), clocks
``checkpoints/``       ``step_<N>.zip`` every ``checkpoint_every`` agent-steps (``--resume`` continues the newest
                       that loads)
``tb/``                TensorBoard logs (``tensorboard --logdir DIR/tb``), when tensorboard is installed
=====================  ===================================================================================

Seeded runs reproduce exactly (one thread; the env, the network and the rollouts are all seeded by ``seed``).
The model, the config files and the checkpoints are written atomically (``agentsim_env.train.checkpoints``), and
a resume writes nothing until its checkpoint has loaded.
"""

from __future__ import annotations

import csv
import io
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agentsim_env.train.callbacks import CURVE_FIELDS, TrainMonitor, read_curve
from agentsim_env.train.checkpoints import (
    Resumed,
    find_resumable,
    latest_checkpoint,
    remove_stale_temps,
    write_atomic,
    write_json_atomic,
    write_model_atomic,
)
from agentsim_env.train.config import TrainConfig, save_config

__all__ = ["TrainResult", "latest_checkpoint", "make_model", "make_vec_env", "save_run", "train"]


@dataclass
class TrainResult:
    """What a training run produced.

    Attributes:
        model: The trained SB3 model.
        config: The config it ran.
        out: The run folder (``None`` when nothing was saved).
        curve: Rows of the learning curve (see ``callbacks.CURVE_FIELDS``).
        timesteps: Agent-steps trained in all (a resumed run included).
        wall_s: Wall seconds of training (a resumed run included).
        cpu_s: Process CPU seconds of training.
        checkpoints: Checkpoints written by this call.
        resumed_from: The checkpoint a resumed run continued (``None``: a fresh run).
        skipped: Newer checkpoints a resumed run skipped because they did not load, with the reason.
    """

    model: Any
    config: TrainConfig
    out: Path | None
    curve: list[dict[str, float]]
    timesteps: int
    wall_s: float
    cpu_s: float
    checkpoints: list[Path] = field(default_factory=list)
    resumed_from: Path | None = None
    skipped: list[tuple[Path, str]] = field(default_factory=list)


def make_vec_env(cfg: TrainConfig) -> Any:
    """The SB3 VecEnv of ``cfg``: ``AgentSimVecEnv`` (native) or the SuperSuit path, seeded with ``cfg.seed``."""
    if cfg.vec == "supersuit":
        from stable_baselines3.common.vec_env import VecMonitor

        from agentsim_env.env.supersuit import supersuit_vec_env

        return VecMonitor(supersuit_vec_env(cfg.scenario, cfg.worlds, seed=cfg.seed, **cfg.env))
    from agentsim_env.env.sb3 import AgentSimVecEnv

    return AgentSimVecEnv(cfg.scenario, cfg.worlds, seed=cfg.seed, **cfg.env)


def make_model(cfg: TrainConfig, vec: Any, tensorboard: str | None = None) -> Any:
    """A fresh ``stable_baselines3.PPO`` (MlpPolicy, CPU) with ``cfg.ppo``'s hyperparameters (and its inbox
    encoder as the features extractor, when ``ppo.inbox_encoder`` names one)."""
    import torch
    from stable_baselines3 import PPO

    p = cfg.ppo
    lr: Any = p.learning_rate
    if p.lr_schedule == "linear":
        lr = _Linear(p.learning_rate)
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[p.activation]
    policy_kwargs: dict[str, Any] = {
        "net_arch": list(p.net_arch),
        "activation_fn": activation,
        "log_std_init": p.log_std_init,
    }
    if p.inbox_encoder != "none":
        from agentsim_env.train.inbox_encoder import InboxEncoder, inbox_layout

        lay = inbox_layout(cfg.scenario, cfg.env)
        policy_kwargs["features_extractor_class"] = InboxEncoder
        policy_kwargs["features_extractor_kwargs"] = {
            "inbox_start": lay.start,
            "inbox_rows": lay.rows,
            "row_features": lay.features,
            "pool": p.inbox_encoder,
            "hidden": p.inbox_hidden,
        }
    return PPO(
        "MlpPolicy",
        vec,
        seed=cfg.seed,
        device="cpu",
        verbose=0,
        tensorboard_log=tensorboard,
        n_steps=p.n_steps,
        batch_size=p.batch_size,
        n_epochs=p.n_epochs,
        learning_rate=lr,
        gamma=p.gamma,
        gae_lambda=p.gae_lambda,
        clip_range=p.clip_range,
        ent_coef=p.ent_coef,
        vf_coef=p.vf_coef,
        max_grad_norm=p.max_grad_norm,
        target_kl=p.target_kl,
        policy_kwargs=policy_kwargs,
    )


class _Linear:
    """A learning rate decaying linearly to 0 (a class, not a closure, so saved models unpickle)."""

    def __init__(self, start: float) -> None:
        self.start = start

    def __call__(self, progress_remaining: float) -> float:
        return self.start * progress_remaining


def _tensorboard_dir(out: Path | None) -> str | None:
    if out is None:
        return None
    try:
        import tensorboard  # noqa: F401  (SB3 writes the event files through torch, which needs it)
    except ImportError:
        return None
    return str(out / "tb")


def _versions() -> dict[str, str]:
    import stable_baselines3
    import torch

    import agentsim_env

    return {
        "agentsim_env": agentsim_env.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "python": platform.python_version(),
    }


#: Files of a run folder that must be files (a folder of that name would fail only at the end of training).
_RUN_FILES = ("model.zip", "config.json", "config.yaml", "curve.csv")


def _check_run_files(out: Path) -> None:
    for name in _RUN_FILES:
        p = out / name
        if (p.exists() or p.is_symlink()) and not p.is_file():
            raise ValueError(f"{str(p)!r} is not a file: move it away (the run writes {name} there)")


def _check_same_config(cfg: TrainConfig, out: Path) -> None:
    """A resumed run must have the config it started with (``timesteps`` aside)."""
    saved = out / "config.yaml"
    if not saved.exists():
        return
    from agentsim_env.train.config import load_config

    before, now = load_config(saved).to_dict(), cfg.to_dict()
    before.pop("timesteps")  # a resumed run may be given a longer budget
    now.pop("timesteps")
    if before != now:
        changed = sorted(k for k in now if now[k] != before.get(k))
        raise ValueError(
            f"--resume: the config differs from the one the run in {str(out)!r} started "
            f"with (config.yaml there) in {changed}; only timesteps may change"
        )


def _curve_upto(out: Path, timesteps: int) -> tuple[bytes | None, dict[str, float]]:
    """``curve.csv`` without the rows past a checkpoint (they are trained again when resuming from it; kept rows
    stay byte for byte as written) nor a last row cut short by a kill, and the clocks of its last kept row.
    Reads only.

    Raises:
        ValueError: A row that is not a curve row, named by its line (before anything is written).
    """
    path = out / "curve.csv"
    clocks = {"wall_s": 0.0, "cpu_s": 0.0, "episodes": 0.0}
    if not path.is_file():
        return None, clocks
    with open(path, encoding="utf-8", newline="") as f:
        header, *rows = f.read().splitlines(keepends=True) or [""]
    if not header.endswith("\n"):  # the header's own write was killed: write it whole (as csv.writer does)
        header = ",".join(CURVE_FIELDS) + "\r\n"
    kept = []
    for line, row in enumerate(rows, start=2):
        if not row.strip() or not row.endswith("\n"):  # blank, or the last row's append was killed half way
            continue
        try:
            step = int(row.split(",", 1)[0])
        except ValueError:
            raise ValueError(
                f"--resume: {str(path)!r} line {line} is not a curve row ({row.strip()[:60]!r}); nothing was changed"
            ) from None
        if step <= timesteps:
            kept.append(row)
    if kept:
        last = next(csv.DictReader(io.StringIO(header + kept[-1])))
        for key in clocks:
            try:
                clocks[key] = float(last.get(key) or 0.0)
            except ValueError:
                pass
    return (header + "".join(kept)).encode("utf-8"), clocks


def _say_resumed(resumed: Resumed, clocks_from_curve: bool) -> None:
    for p, reason in resumed.skipped:
        print(f"--resume: skipped {p.name}: {reason}", file=sys.stderr)
    if clocks_from_curve:
        print(
            f"--resume: {resumed.path.with_suffix('.json').name} is missing or not valid: the clocks and "
            "episode count continue from curve.csv",
            file=sys.stderr,
        )
    print(
        f"--resume: continuing from {resumed.path.name} ({int(resumed.model.num_timesteps):,} agent-steps)",
        file=sys.stderr,
    )


def _resume(cfg: TrainConfig, path: Path, vec: Any) -> tuple[Resumed, bytes | None, dict[str, float]]:
    """Load the newest checkpoint of ``path`` that loads, and prepare the curve to continue; writes nothing."""
    from agentsim_env.policies.learned import load_model

    _check_same_config(cfg, path)
    tensorboard = _tensorboard_dir(path)
    resumed = find_resumable(path, lambda p: load_model(p, env=vec, device="cpu", tensorboard_log=tensorboard))
    curve, curve_clocks = _curve_upto(path, int(resumed.model.num_timesteps))
    return resumed, curve, resumed.clocks or curve_clocks


def save_run(model: Any, cfg: TrainConfig, path: Path, *, wall_s: float, cpu_s: float) -> Path:
    """Write ``model.zip`` and ``config.json`` (what it was trained on, versions, budget) into ``path``, each
    atomically, so that the folder loads as a policy (``agentsim run --policy PATH``); returns the model's path."""
    write_model_atomic(model, path / "model.zip")
    meta = {
        "scenario": cfg.scenario,
        "env": cfg.env,
        "train": cfg.to_dict(),
        "versions": _versions(),
        "timesteps_done": int(model.num_timesteps),
        "wall_s": round(wall_s, 3),
        "cpu_s": round(cpu_s, 3),
        "machine": platform.processor() or platform.machine(),
    }
    write_json_atomic(path / "config.json", meta)
    return path / "model.zip"


def train(
    cfg: TrainConfig,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    progress: bool = False,
    desc: str | None = None,
    record: str | Path | None = None,
) -> TrainResult:
    """Train PPO as ``cfg`` says.

    Args:
        cfg: The training config.
        out: Run folder (created); ``None`` trains without writing anything.
        resume: Continue from the newest checkpoint in ``out`` that loads (its config must equal ``cfg``): newer
            ones that do not load are skipped, each named with the reason on stderr; nothing in ``out`` (nor the
            ``record`` store) is written before the checkpoint has loaded.
        progress: Show the progress bar with the live mean return.
        desc: Text before the bar (default: the scenario).
        record: An SQLite store to record the training env to (every world, every step, automatic resets as new
            episodes; one run, marked ``complete`` when training ends). Native vector env only.

    Returns:
        The result; the model is also saved as ``out/model.zip`` with ``config.json``.

    Raises:
        ValueError: ``resume`` without a checkpoint that loads (each is named with its reason) or with another
            config; a file of the run folder that is a folder.
    """
    import torch

    torch.set_num_threads(1)
    path = None if out is None else Path(out)
    if resume and path is None:
        raise ValueError("resume needs the run folder (--out) holding the checkpoints")
    if record is not None and cfg.vec != "native":
        raise ValueError("recording the training env needs vec: native")
    if path is not None:
        _check_run_files(path)
    vec = make_vec_env(cfg)
    try:
        return _train(cfg, path, vec, resume=resume, progress=progress, desc=desc, record=record)
    except BaseException:
        vec.close()
        raise


def _train(
    cfg: TrainConfig,
    path: Path | None,
    vec: Any,
    *,
    resume: bool,
    progress: bool,
    desc: str | None,
    record: str | Path | None,
) -> TrainResult:
    clocks = {"wall_s": 0.0, "cpu_s": 0.0, "episodes": 0.0}
    resumed: Resumed | None = None
    if resume:
        assert path is not None
        resumed, curve_bytes, clocks = _resume(cfg, path, vec)
        model = resumed.model
    # from here on the run goes ahead: the folder may change
    if path is not None:
        path.mkdir(parents=True, exist_ok=True)
        for folder in (path, path / "checkpoints"):
            remove_stale_temps(folder)  # what writes killed half way left
    if resumed is not None:
        assert path is not None
        _say_resumed(resumed, clocks_from_curve=resumed.clocks is None)
        if curve_bytes is not None:
            write_atomic(path / "curve.csv", lambda tmp: tmp.write_bytes(curve_bytes))
    else:
        if path is not None and (path / "curve.csv").exists():
            (path / "curve.csv").unlink()  # a fresh run starts a fresh curve
        model = make_model(cfg, vec, _tensorboard_dir(path))
    recorded: Any = None
    if record is not None:
        from agentsim_env.recorder import record as record_env

        label = f"agentsim train {cfg.scenario} worlds={cfg.worlds} seed={cfg.seed}"
        recorded = vec.batch = record_env(vec.batch, record, label=label)  # the VecEnv steps the recorded env
    if path is not None:
        write_atomic(path / "config.yaml", lambda tmp: save_config(cfg, tmp))
    monitor = TrainMonitor(
        path,
        checkpoint_every=cfg.checkpoint_every,
        progress=progress,
        desc=desc or cfg.scenario,
        start_wall=clocks["wall_s"],
        start_cpu=clocks["cpu_s"],
        episodes_done=int(clocks["episodes"]),
    )
    left = max(cfg.timesteps - int(model.num_timesteps), 0)
    t0 = time.perf_counter()
    try:
        if left > 0:
            model.learn(total_timesteps=left, callback=monitor, reset_num_timesteps=not resume, tb_log_name="ppo")
    except BaseException:
        if recorded is not None:
            recorded.recorder.finish("incomplete")
        raise
    if recorded is not None:
        recorded.close()  # the run is complete
    wall = clocks["wall_s"] + (time.perf_counter() - t0)
    cpu = monitor.cpu_s() if monitor.started else clocks["cpu_s"]
    curve: list[dict[str, float]] = []
    if path is not None:
        save_run(model, cfg, path, wall_s=wall, cpu_s=cpu)
        if (path / "curve.csv").exists():
            curve = read_curve(path / "curve.csv")
    vec.close()
    return TrainResult(
        model,
        cfg,
        path,
        curve,
        int(model.num_timesteps),
        wall,
        cpu,
        monitor.checkpoints,
        resumed_from=None if resumed is None else resumed.path,
        skipped=[] if resumed is None else resumed.skipped,
    )
