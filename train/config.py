"""Training configs: typed, frozen dataclasses loaded from YAML and validated with the field named.

A config file (shipped ones live in ``train/configs/``, installed as ``agentsim_env/train/configs``)::

    scenario: navigation      # a registered scenario
    timesteps: 2000000        # agent-steps, summed over every agent of every world
    worlds: 16                # worlds stepped together; SB3 sees worlds x n_agents entries
    seed: 0                   # seeds the envs and the network; a seeded run reproduces exactly
    vec: native               # native (AgentSimVecEnv over BatchedEnv) | supersuit (the PettingZoo tutorial path)
    env: {n_agents: 4}        # scenario config keys, as agentsim_env.make(scenario, **env) takes them
    ppo: {n_steps: 64, batch_size: 512, learning_rate: 3.0e-4, net_arch: [64, 64], activation: tanh}
    checkpoint_every: 500000  # agent-steps between checkpoints (0: none)
    eval: {seeds: 20, first_seed: 1000, env: {}, baseline_env: {}, baselines: all}

``ppo`` holds the fields of ``PPOConfig`` (the common ``stable_baselines3.PPO`` arguments plus ``net_arch`` and
``activation``); every key of every section is checked, and an unknown one is an error listing the allowed keys.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import field
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

from agentsim_env.core.config_model import Choice, Int, Real, Text, config
from agentsim_env.core.validation import short_repr

__all__ = [
    "ACTIVATIONS",
    "CONFIG_DIR",
    "INBOX_ENCODERS",
    "VEC_KINDS",
    "EvalConfig",
    "PPOConfig",
    "TrainConfig",
    "load_config",
    "read_config_data",
    "save_config",
    "shipped_configs",
]

#: Where the shipped configs live (``<name>.yaml``).
CONFIG_DIR = Path(__file__).resolve().parent / "configs"
VecKind = Annotated[Literal["native", "supersuit"], Choice]
#: Vector-env paths ``vec`` may name.
VEC_KINDS: tuple[str, ...] = typing.get_args(typing.get_args(VecKind)[0])
InboxEncoderKind = Annotated[Literal["none", "mean", "max", "attention"], Choice]
#: Inbox encoders ``ppo.inbox_encoder`` may name (``agentsim_env.train.inbox_encoder``).
INBOX_ENCODERS: tuple[str, ...] = typing.get_args(typing.get_args(InboxEncoderKind)[0])
Activation = Annotated[Literal["tanh", "relu"], Choice]
#: Activation functions ``ppo.activation`` may name.
ACTIVATIONS: tuple[str, ...] = typing.get_args(typing.get_args(Activation)[0])
Fraction = Annotated[Real, Field(ge=0.0, le=1.0)]
"""A number in [0, 1]."""
Steps = Annotated[Int, Field(ge=0, le=10_000_000_000)]
"""Agent-steps, 0..10^10."""


@config("ppo")
class PPOConfig:
    """PPO hyperparameters (``stable_baselines3.PPO`` keyword arguments of the same names).

    Attributes:
        n_steps: Steps per env entry per rollout, 1..100,000 (a rollout is ``n_steps x worlds x n_agents``).
        batch_size: Minibatch size, 1..10,000,000.
        n_epochs: Passes over each rollout, 1..1,000.
        learning_rate: Adam step size, in (0, 1].
        lr_schedule: ``constant`` or ``linear`` (decays to 0 at ``timesteps``).
        gamma: Discount, in [0, 1].
        gae_lambda: GAE lambda, in [0, 1].
        clip_range: PPO clip, in (0, 10].
        ent_coef: Entropy bonus, 0..10.
        vf_coef: Value loss weight, 0..100.
        max_grad_norm: Gradient clipping norm, in (0, 1e6].
        target_kl: Early stop of an update past this KL (``None``: never), in (0, 10].
        net_arch: Hidden layer widths of the policy and value networks, 1..8 layers of 1..4096.
        activation: ``tanh`` or ``relu``.
        log_std_init: Initial log standard deviation of the Gaussian actions, -10..10.
        inbox_encoder: How the network reads the inbox: ``none`` (the flat vector into the MLP, as before),
            or each message row through a shared MLP pooled by ``mean``, ``max`` or ``attention`` (one head,
            learned query); see ``agentsim_env.train.inbox_encoder``. Needs a scenario with comms.
        inbox_hidden: Width of the inbox encoder's row code, 1..1024.
    """

    n_steps: Annotated[Int, Field(ge=1, le=100_000)] = 64
    batch_size: Annotated[Int, Field(ge=1, le=10_000_000)] = 512
    n_epochs: Annotated[Int, Field(ge=1, le=1000)] = 10
    learning_rate: Annotated[Real, Field(gt=0.0, le=1.0)] = 3e-4
    lr_schedule: Annotated[Literal["constant", "linear"], Choice] = "constant"
    gamma: Fraction = 0.98
    gae_lambda: Fraction = 0.95
    clip_range: Annotated[Real, Field(gt=0.0, le=10.0)] = 0.2
    ent_coef: Annotated[Real, Field(ge=0.0, le=10.0)] = 0.0
    vf_coef: Annotated[Real, Field(ge=0.0, le=100.0)] = 0.5
    max_grad_norm: Annotated[Real, Field(gt=0.0, le=1e6)] = 0.5
    target_kl: Annotated[Real, Field(gt=0.0, le=10.0)] | None = None
    net_arch: Annotated[tuple[Annotated[Int, Field(ge=1, le=4096)], ...], Field(min_length=1, max_length=8)] = (
        64,
        64,
    )
    activation: Activation = "tanh"
    log_std_init: Annotated[Real, Field(ge=-10.0, le=10.0)] = 0.0
    inbox_encoder: InboxEncoderKind = "none"
    inbox_hidden: Annotated[Int, Field(ge=1, le=1024)] = 32


@config("eval")
class EvalConfig:
    """The evaluation at the end of training (and of ``agentsim train --eval-only``).

    Attributes:
        seeds: Episodes per policy, on seeds ``first_seed`` .. ``first_seed + seeds - 1``; 1..10,000.
        first_seed: Seed of the first evaluation episode, >= 0 (apart from training's seeds by default).
        env: Scenario config keys for every evaluation episode, over the training ``env``.
        baseline_env: Keys for the scripted baselines' episodes only, over ``env`` (for a learned mode
            that the scripted policies do not use).
        baselines: ``all`` (every scripted baseline of the scenario), ``default`` (the scenario's default
            baseline), ``none``, or a comma-separated list (``agentsim train --eval-baselines`` sets it).
    """

    seeds: Annotated[Int, Field(ge=1, le=10_000)] = 20
    first_seed: Annotated[Int, Field(ge=0, le=2**63 - 1)] = 1000
    env: dict[str, Any] = field(default_factory=dict)
    baseline_env: dict[str, Any] = field(default_factory=dict)
    baselines: Text = "all"

    def seed_list(self) -> list[int]:
        """The evaluation seeds."""
        return list(range(self.first_seed, self.first_seed + self.seeds))


@config()
class TrainConfig:
    """One training run: scenario, budget, PPO, checkpoints and the final evaluation.

    Attributes:
        scenario: A registered scenario name.
        timesteps: Agent-steps to train, 1..10,000,000,000.
        worlds: Worlds stepped together (native) or env copies (supersuit), 1..4,096.
        seed: Seed of the envs and the network, >= 0.
        vec: ``native`` or ``supersuit``.
        env: Scenario config keys (checked by building the scenario's config).
        ppo: PPO hyperparameters.
        checkpoint_every: Agent-steps between checkpoints (0: only the final model), >= 0.
        eval: The final evaluation.
    """

    nested: ClassVar[dict[str, type]] = {"ppo": PPOConfig, "eval": EvalConfig}

    scenario: Text = "navigation"
    timesteps: Annotated[Steps, Field(ge=1)] = 1_000_000
    worlds: Annotated[Int, Field(ge=1, le=4096)] = 16
    seed: Annotated[Int, Field(ge=0, le=2**32 - 1)] = 0
    vec: VecKind = "native"
    env: dict[str, Any] = field(default_factory=dict)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    checkpoint_every: Steps = 500_000  # 0: only the final model
    eval: EvalConfig = field(default_factory=EvalConfig)

    def __post_init__(self) -> None:
        from agentsim_env.scenarios.registry import list_scenarios, make_scenario

        names = list_scenarios()
        if self.scenario not in names:
            raise ValueError(f"scenario must be one of {names}, got {short_repr(self.scenario)}")
        checked: list[dict[str, Any]] = []
        for where, keys in (
            ("env", self.env),
            ("eval.env", self.eval_env()),
            ("eval.baseline_env", self.eval_env(baseline=True)),
        ):
            if keys in checked:  # the evaluation adds nothing: already built once
                continue
            checked.append(keys)
            try:
                built = make_scenario(self.scenario, **dict(keys))
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: {exc}") from None
            if self.ppo.inbox_encoder != "none" and "inbox" not in built.obs_parts():
                raise ValueError(
                    f"ppo.inbox_encoder {self.ppo.inbox_encoder!r} needs an inbox, and {self.scenario!r} has none "
                    f"with {where}; give it comms (env.comms) or set ppo.inbox_encoder to 'none'"
                )

    def eval_env(self, baseline: bool = False) -> dict[str, Any]:
        """Scenario keys of the evaluation episodes: ``env``, then ``eval.env`` (then ``eval.baseline_env``)."""
        keys = _deep_merge(self.env, self.eval.env)
        return _deep_merge(keys, self.eval.baseline_env) if baseline else keys

    def to_dict(self) -> dict[str, Any]:
        """Plain data (lists for tuples), as written to ``config.yaml`` next to a trained model."""
        return _plain(dataclasses.asdict(self))

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with ``changes`` (sections may be given as dicts of some of their fields)."""
        merged = self.to_dict()
        for key, value in changes.items():
            if key in self.nested and isinstance(value, dict):
                merged[key] = {**merged[key], **value}
            else:
                merged[key] = value
        return _build(TrainConfig, merged, "")


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _build(cls: type, data: Any, where: str) -> Any:
    """``cls(**data)`` with unknown keys and non-mappings reported by name (sections too, as ``ppo.lr``)."""
    _check_keys(cls, data, where)
    return cls(**data)


def _check_keys(cls: type, data: Any, where: str) -> None:
    """Raise on a non-mapping or an unknown key of ``cls`` or of one of its sections given as a mapping."""
    if not isinstance(data, dict):
        raise ValueError(f"{where.rstrip('.') or 'the config'} must be a mapping of keys, got {type(data).__name__}")
    allowed = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(allowed), key=repr)  # YAML keys may mix types (1 and "a")
    if unknown:
        first = unknown[0] if isinstance(unknown[0], str) and len(unknown[0]) <= 60 else short_repr(unknown[0], 60)
        raise ValueError(f"unknown key {where}{first}; allowed: {allowed}")
    for key, value in data.items():
        if key in ("env", "baseline_env") and not isinstance(value, dict):
            raise ValueError(f"{where}{key} must be a mapping of scenario config keys, got {type(value).__name__}")
        section = getattr(cls, "nested", {}).get(key)
        if section is not None and isinstance(value, dict):
            _check_keys(section, value, f"{where}{key}.")


def shipped_configs() -> dict[str, Path]:
    """The shipped configs: name -> path (``train/configs/<name>.yaml``)."""
    return {p.stem: p for p in sorted(CONFIG_DIR.glob("*.yaml"))}


def read_config_data(source: str | Path | dict[str, Any] | None, scenario: str | None = None) -> dict[str, Any]:
    """The keys of a config source, unchecked: a YAML path, a shipped config's name, a dict (copied), or ``None``
    (the shipped config named like ``scenario``, else ``{}``).

    Raises:
        ValueError: A missing or unreadable file, bad YAML or one past the loader's bounds, not a mapping.
    """
    data: dict[str, Any]
    if source is None:
        shipped = shipped_configs()
        source = shipped.get(scenario or "") or {}
    if isinstance(source, dict):
        data = dict(source)
    else:
        path = Path(source)
        if not path.suffix and str(source) in shipped_configs():
            path = shipped_configs()[str(source)]
        try:
            found = path.exists()
        except OSError as exc:  # e.g. a name too long for the file system
            raise ValueError(f"config file {short_repr(str(source))}: {exc.strerror}") from None
        if not found:
            raise ValueError(
                f"config file {short_repr(str(source))} not found; shipped configs: {list(shipped_configs())}"
            )
        from agentsim_env.train.yaml_load import load_yaml_file

        # bounded: size, depth, aliases expanded, duplicate keys (a device or FIFO is refused, never read)
        try:
            loaded = load_yaml_file(path, f"config file {short_repr(str(path))}")
        except OSError as exc:  # unreadable: one line, as for every other bad file
            raise ValueError(f"config file {short_repr(str(path))}: {exc.strerror}") from None
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ValueError(f"config file {str(path)!r} must hold a mapping of keys, got {type(loaded).__name__}")
        data = loaded
    return data


def load_config(
    source: str | Path | dict[str, Any] | None = None,
    overrides: dict[str, Any] | None = None,
    *,
    scenario: str | None = None,
) -> TrainConfig:
    """Load a training config.

    Args:
        source: A YAML path, the name of a shipped config (``navigation``, ``relay``, ...), a dict, or ``None``
            (the shipped config named like ``scenario``, else the defaults).
        overrides: Keys over the loaded ones (sections as dicts of some fields, e.g. ``{"ppo": {"n_steps": 32}}``).
        scenario: The scenario, when the file does not name one; it must agree when both do.

    Returns:
        The validated config.

    Raises:
        ValueError: A missing file, bad YAML, a file outside the bounds of ``agentsim_env.train.yaml_load``
            (1 MiB, 32 levels, 10,000 values with aliases expanded, no duplicate keys), an unknown key or a bad
            value (the message names it).
    """
    data = read_config_data(source, scenario)
    if scenario is not None:
        if data.get("scenario", scenario) != scenario:
            raise ValueError(f"the config is for scenario {short_repr(data['scenario'])}, not {scenario!r}")
        data["scenario"] = scenario
    for key, value in (overrides or {}).items():
        if key in TrainConfig.nested and isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        elif key == "env" and isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = _deep_merge(data[key], value)
        else:
            data[key] = value
    return _build(TrainConfig, data, "")


def _deep_merge(base: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in new.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def save_config(cfg: TrainConfig, path: str | Path) -> Path:
    """Write ``cfg`` as YAML (loadable again with ``load_config``)."""
    import yaml

    p = Path(path)
    p.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False), encoding="utf-8")
    return p
