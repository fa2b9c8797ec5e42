"""Train PPO with parameter sharing on a scenario, from a ``TrainConfig``; save, checkpoint, resume.

Every agent of every world is one entry of an SB3 ``VecEnv`` (the native ``AgentSimVecEnv`` over the batched
env, or SuperSuit's path with ``vec: supersuit``), so one network is trained on all agents. A run folder holds:

=====================  ===================================================================================
``model.zip``          the trained model (SB3 format; loads as a policy: ``agentsim run --policy DIR``)
``config.json``        scenario, scenario config, the whole training config, versions, budget used
``config.yaml``        the training config, re-runnable with ``agentsim train --config``
``curve.csv``          one row per rollout: agent-steps, episodes, mean return (last 100 episodes), clocks
``checkpoints/``       ``step_<N>.zip`` every ``checkpoint_every`` agent-steps (``--resume`` continues the newest)
``tb/``                TensorBoard logs (``tensorboard --logdir DIR/tb``), when tensorboard is installed
=====================  ===================================================================================

Seeded runs reproduce exactly (one thread; the env, the network and the rollouts are all seeded by ``seed``).
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agentsim_env.train.callbacks import TrainMonitor, read_curve
from agentsim_env.train.config import TrainConfig, save_config

__all__ = ["TrainResult", "latest_checkpoint", "make_model", "make_vec_env", "train"]


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
    """

    model: Any
    config: TrainConfig
    out: Path | None
    curve: list[dict[str, float]]
    timesteps: int
    wall_s: float
    cpu_s: float
    checkpoints: list[Path] = field(default_factory=list)


def make_vec_env(cfg: TrainConfig) -> Any:
    """The SB3 VecEnv of ``cfg``: ``AgentSimVecEnv`` (native) or the SuperSuit path, seeded with ``cfg.seed``."""
    if cfg.vec == "supersuit":
        from stable_baselines3.common.vec_env import VecMonitor

        from agentsim_env.env.supersuit import supersuit_vec_env

        return VecMonitor(supersuit_vec_env(cfg.scenario, cfg.worlds, seed=cfg.seed, **cfg.env))
    from agentsim_env.env.sb3 import AgentSimVecEnv

    return AgentSimVecEnv(cfg.scenario, cfg.worlds, seed=cfg.seed, **cfg.env)


def make_model(cfg: TrainConfig, vec: Any, tensorboard: str | None = None) -> Any:
    """A fresh ``stable_baselines3.PPO`` (MlpPolicy, CPU) with ``cfg.ppo``'s hyperparameters."""
    import torch
    from stable_baselines3 import PPO

    p = cfg.ppo
    lr: Any = p.learning_rate
    if p.lr_schedule == "linear":
        lr = _Linear(p.learning_rate)
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[p.activation]
    return PPO(
        "MlpPolicy", vec, seed=cfg.seed, device="cpu", verbose=0, tensorboard_log=tensorboard,
        n_steps=p.n_steps, batch_size=p.batch_size, n_epochs=p.n_epochs, learning_rate=lr, gamma=p.gamma,
        gae_lambda=p.gae_lambda, clip_range=p.clip_range, ent_coef=p.ent_coef, vf_coef=p.vf_coef,
        max_grad_norm=p.max_grad_norm, target_kl=p.target_kl,
        policy_kwargs={"net_arch": list(p.net_arch), "activation_fn": activation, "log_std_init": p.log_std_init},
    )  # fmt: skip


class _Linear:
    """A learning rate decaying linearly to 0 (a class, not a closure, so saved models unpickle)."""

    def __init__(self, start: float) -> None:
        self.start = start

    def __call__(self, progress_remaining: float) -> float:
        return self.start * progress_remaining


def latest_checkpoint(out: str | Path) -> Path | None:
    """The newest ``checkpoints/step_<N>.zip`` of a run folder (``None`` when there is none)."""
    folder = Path(out) / "checkpoints"
    found = [(int(p.stem.split("_")[1]), p) for p in folder.glob("step_*.zip") if p.stem.split("_")[1].isdigit()]
    return max(found)[1] if found else None


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

    return {"agentsim_env": agentsim_env.__version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__, "python": platform.python_version()}  # fmt: skip


def _truncate_curve(out: Path, timesteps: int) -> None:
    """Drop curve rows past a checkpoint (they are trained again when resuming from it); kept rows stay as written."""
    path = out / "curve.csv"
    if not path.exists():
        return
    header, *rows = path.read_text(encoding="utf-8").splitlines(keepends=True)
    path.write_text(header + "".join(r for r in rows if int(r.split(",", 1)[0]) <= timesteps), encoding="utf-8")


def train(cfg: TrainConfig, out: str | Path | None = None, *, resume: bool = False, progress: bool = False,
          desc: str | None = None, record: str | Path | None = None) -> TrainResult:  # fmt: skip
    """Train PPO as ``cfg`` says.

    Args:
        cfg: The training config.
        out: Run folder (created); ``None`` trains without writing anything.
        resume: Continue from the newest checkpoint in ``out`` (its config must equal ``cfg``); without one,
            an error.
        progress: Show the progress bar with the live mean return.
        desc: Text before the bar (default: the scenario).
        record: An SQLite store to record the training env to (every world, every step, automatic resets as new
            episodes; one run, marked ``complete`` when training ends). Native vector env only.

    Returns:
        The result; the model is also saved as ``out/model.zip`` with ``config.json``.

    Raises:
        ValueError: ``resume`` without a checkpoint or with another config.
    """
    import torch

    torch.set_num_threads(1)
    path = None if out is None else Path(out)
    if path is not None:
        path.mkdir(parents=True, exist_ok=True)
    vec = make_vec_env(cfg)
    recorded: Any = None
    if record is not None:
        if cfg.vec != "native":
            raise ValueError("recording the training env needs vec: native")
        from agentsim_env.recorder import record as record_env

        label = f"agentsim train {cfg.scenario} worlds={cfg.worlds} seed={cfg.seed}"
        recorded = vec.batch = record_env(vec.batch, record, label=label)  # the VecEnv steps the recorded env
    clocks = {"wall_s": 0.0, "cpu_s": 0.0, "episodes": 0}
    if resume:
        if path is None:
            raise ValueError("resume needs the run folder (--out) holding the checkpoints")
        ckpt = latest_checkpoint(path)
        if ckpt is None:
            raise ValueError(f"--resume: no checkpoint in {str(path / 'checkpoints')!r}")
        saved = path / "config.yaml"
        if saved.exists():
            from agentsim_env.train.config import load_config

            before, now = load_config(saved).to_dict(), cfg.to_dict()
            before.pop("timesteps")  # a resumed run may be given a longer budget
            now.pop("timesteps")
            if before != now:
                changed = sorted(k for k in now if now[k] != before.get(k))
                raise ValueError(f"--resume: the config differs from the one the run in {str(path)!r} started "
                                 f"with (config.yaml there) in {changed}; only timesteps may change")  # fmt: skip
        from stable_baselines3 import PPO

        model = PPO.load(ckpt, env=vec, device="cpu", tensorboard_log=_tensorboard_dir(path))
        if ckpt.with_suffix(".json").exists():
            clocks.update(json.loads(ckpt.with_suffix(".json").read_text(encoding="utf-8")))
        _truncate_curve(path, model.num_timesteps)
    else:
        if path is not None and (path / "curve.csv").exists():
            (path / "curve.csv").unlink()  # a fresh run starts a fresh curve
        model = make_model(cfg, vec, _tensorboard_dir(path))
    if path is not None:
        save_config(cfg, path / "config.yaml")
    monitor = TrainMonitor(path, checkpoint_every=cfg.checkpoint_every, progress=progress,
                           desc=desc or cfg.scenario, start_wall=clocks["wall_s"], start_cpu=clocks["cpu_s"],
                           episodes_done=int(clocks["episodes"]))  # fmt: skip
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
        model.save(path / "model.zip")
        meta = {"scenario": cfg.scenario, "env": cfg.env, "train": cfg.to_dict(), "versions": _versions(),
                "timesteps_done": int(model.num_timesteps), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
                "machine": platform.processor() or platform.machine()}  # fmt: skip
        (path / "config.json").write_text(json.dumps(meta, indent=2), encoding="utf-8")
        if (path / "curve.csv").exists():
            curve = read_curve(path / "curve.csv")
    vec.close()
    return TrainResult(model, cfg, path, curve, int(model.num_timesteps), wall, cpu, monitor.checkpoints)
