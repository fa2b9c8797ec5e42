"""Trained models as policies: a stable-baselines3 model saved by ``agentsim train`` acts like a scripted one.

A trained model is a folder (``agentsim train --out DIR`` writes ``DIR/model.zip`` and ``DIR/config.json``) or
the ``model.zip`` itself (its ``config.json`` beside it; a checkpoint ``DIR/checkpoints/step_N.zip`` finds
``DIR/config.json`` one folder up). ``config.json`` names the scenario and the scenario config the model was
trained on (``{"scenario": ..., "env": {...}, ...}``); the observation and action layouts must match the env it is
asked to drive, else loading fails with both layouts named.

The policy flattens each agent's observation (Dict parts concatenated in the scenario's declaration order, the
same layout as ``obs_format="flat"`` and the batched env) and predicts every live agent's action in one batch,
deterministically by default; actions come back as Dicts or flat vectors, as the env takes them.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.env.spaces import flat_layout

__all__ = [
    "LearnedPolicy",
    "ModelFileError",
    "is_model_path",
    "load_model",
    "load_policy",
    "model_env_config",
    "model_files",
]

#: Largest ``config.json`` beside a model read (it holds a training config: a few kilobytes).
MAX_CONFIG_JSON_BYTES = 1 << 20
#: Fewest rows of one forward pass in ``act_rows`` (fewer are padded): a row's action is then the same whatever
#: else is in the batch.
_MIN_ROWS = 16
#: Parts every stable-baselines3 model zip holds (the class parameters and the policy's weights).
_REQUIRED_PARTS = ("data", "policy.pth")


def is_model_path(name: str | Path) -> bool:
    """Whether a policy name refers to a trained model (a ``.zip`` file or a folder) rather than a baseline."""
    text = str(name)
    return text.endswith(".zip") or "/" in text or "\\" in text or Path(text).is_dir()


def model_files(path: str | Path) -> tuple[Path, Path]:
    """The ``model.zip`` and ``config.json`` of a trained model.

    Args:
        path: The model folder or its ``.zip`` (a checkpoint's config is looked up one folder up).

    Returns:
        ``(zip_path, config_path)``.

    Raises:
        ValueError: When either file is missing.
    """
    p = Path(path)
    if p.is_dir() and p.suffix == ".zip":
        raise ValueError(f"trained model {str(p)!r} is a folder, not a model .zip file")
    if p.is_dir():
        zip_path = p / "model.zip"
        if not zip_path.is_file():
            raise ValueError(f"trained model folder {str(p)!r} has no model.zip (train one with 'agentsim train')")
    elif p.suffix == ".zip":
        if not p.is_file():
            raise ValueError(f"trained model {str(p)!r} does not exist")
        zip_path = p
    else:
        raise ValueError(f"a trained model is a folder with model.zip or a .zip file, got {str(p)!r}")
    for folder in (zip_path.parent, zip_path.parent.parent):
        if (folder / "config.json").is_file():
            return zip_path, folder / "config.json"
    raise ValueError(f"no config.json next to {str(zip_path)!r} (it names the scenario the model was trained on)")


def _read_config(path: Path) -> dict[str, Any]:
    from agentsim_env.core.files import parse_json, read_regular

    try:  # bounded like every config file: size, regular file, duplicate keys, depth
        meta = parse_json(read_regular(path, MAX_CONFIG_JSON_BYTES, "a model's config.json").decode("utf-8"), 32)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{str(path)!r} is not a readable JSON file: {exc}") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("scenario"), str):
        raise ValueError(f"{str(path)!r} must be a JSON object naming the 'scenario'")
    if not isinstance(meta.get("env", {}), dict):
        raise ValueError(f"{str(path)!r}: 'env' must be an object of scenario config keys")
    return meta


def model_env_config(path: str | Path) -> tuple[str, dict[str, Any]]:
    """The scenario and scenario config keys a trained model was trained with.

    Args:
        path: The model folder or ``.zip``.

    Returns:
        ``(scenario, env_config)``.
    """
    meta = _read_config(model_files(path)[1])
    return meta["scenario"], dict(meta.get("env", {}))


class ModelFileError(ValueError):
    """A model file that does not load, with the reason in words (``reason``: e.g. "not a valid zip file").

    Args:
        path: The file.
        reason: What is wrong with it.
    """

    def __init__(self, path: Path, reason: str) -> None:
        super().__init__(f"trained model {str(path)!r} cannot be loaded: {reason}")
        self.path = path
        self.reason = reason


def _damage(path: Path) -> str | None:
    """What makes ``path`` unreadable as a model zip, checked cheaply before loading (``None``: nothing found)."""
    if not path.exists():
        return "it does not exist"
    if not path.is_file():
        return "it is a folder, not a file" if path.is_dir() else "it is not a regular file"
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()  # every part's CRC: a truncated or overwritten part is named here
            names = set(archive.namelist())
    except (zipfile.BadZipFile, zlib.error, EOFError, ValueError):
        return "not a valid zip file"  # truncated, or not a model at all
    except OSError as exc:
        return f"it cannot be read ({exc.strerror or exc})"
    if bad is not None:
        return f"{bad} is damaged (its checksum does not match)"
    missing = [n for n in _REQUIRED_PARTS if n not in names]
    if missing:
        return f"not a stable-baselines3 model (no {', '.join(missing)} in the zip)"
    return None


def _diagnose(path: Path, exc: Exception) -> str:
    """Which part of a well-formed model zip made loading fail (the loader's own message names none)."""
    import torch

    with zipfile.ZipFile(path) as archive:
        try:
            json.loads(archive.read("data"))
        except ValueError:
            return "data is not valid JSON"
        for name in archive.namelist():
            if name.endswith(".pth"):
                try:
                    with archive.open(name) as f:
                        torch.load(f, map_location="cpu", weights_only=True)
                except Exception:  # noqa: BLE001 - torch raises many kinds for a damaged file
                    return f"{name} is not a valid PyTorch file"
    first = (str(exc).strip().splitlines() or [""])[0]
    return f"{type(exc).__name__}: {first[:300]}"


def load_model(path: str | Path, **kwargs: Any) -> Any:
    """``stable_baselines3.PPO.load`` with one clear error for a damaged file.

    Args:
        path: The model ``.zip`` (``model.zip`` or a checkpoint).
        **kwargs: Passed to ``PPO.load`` (``env``, ``device``, ``tensorboard_log``...).

    Returns:
        The loaded model.

    Raises:
        ModelFileError: The file is missing, a folder, not a zip, damaged, or holds parts that do not load; the
            message names the file and the part.
        ImportError: stable-baselines3 is not installed.
    """
    try:
        from stable_baselines3 import PPO
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError('trained policies need stable-baselines3: pip install "agentsim-env[train]"') from exc
    p = Path(path)
    reason = _damage(p)
    if reason is not None:
        raise ModelFileError(p, reason)
    try:
        return PPO.load(p, **kwargs)
    except Exception as exc:  # noqa: BLE001 - whatever the loader raises, the file is what is named
        raise ModelFileError(p, _diagnose(p, exc)) from None


class LearnedPolicy:
    """A trained SB3 model acting through the ``Policy`` protocol.

    Args:
        model: A stable-baselines3 algorithm (anything with ``predict(obs, deterministic=)``).
        env: The ParallelEnv it drives (its scenario's parts give the layouts).
        deterministic: Act on the mode of the action distribution (``False``: sample).
        name: Shown in tables (the model folder's name).
    """

    def __init__(self, model: Any, env: Any, *, deterministic: bool = True, name: str = "learned") -> None:
        self.model = model
        self.name = name
        self.deterministic = deterministic
        scenario = env.scenario
        self._obs_keys = list(scenario.obs_parts())
        self._obs_dim = sum(p.size for p in scenario.obs_parts().values())
        self._act_layout = flat_layout(scenario.act_parts())
        self._act_shapes = {k: p.shape for k, p in scenario.act_parts().items()}
        self._dict_actions = getattr(env, "action_format", "dict") == "dict"
        want = (self._obs_dim,)
        got_obs = tuple(getattr(model.observation_space, "shape", ()) or ())
        got_act = tuple(getattr(model.action_space, "shape", ()) or ())
        act_dim = sum(s.stop - s.start for s in self._act_layout.values())
        if got_obs != want or got_act != (act_dim,):
            raise ValueError(
                f"the model was trained on observations {got_obs} and actions {got_act}, but this "
                f"{scenario.name} env has observations {want} and actions {(act_dim,)}: build the env with the "
                "config the model was trained on (its config.json 'env')"
            )

    @classmethod
    def for_env(cls, env: Any, path: str | Path, deterministic: bool = True) -> LearnedPolicy:
        """Load the model at ``path`` (folder or ``.zip``) for ``env``; see ``load_policy``."""
        return load_policy(path, env, deterministic=deterministic)

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset (the network is stateless); a stochastic policy is reseeded."""
        if seed is not None and not self.deterministic:
            self.model.set_random_seed(seed)

    def _flat(self, obs: Any) -> np.ndarray:
        if isinstance(obs, dict):
            return np.concatenate([np.asarray(obs[k], dtype=np.float32).reshape(-1) for k in self._obs_keys])
        return np.asarray(obs, dtype=np.float32).reshape(-1)

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Actions of every agent in ``observations`` (one batched forward pass)."""
        if not observations:
            return {}
        agents = list(observations)
        batch = np.stack([self._flat(observations[a]) for a in agents])
        actions = self._predict(batch)
        if not self._dict_actions:
            return dict(zip(agents, actions))
        return {a: {k: row[sl] for k, sl in self._act_layout.items()} for a, row in zip(agents, actions)}

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of a batch of agents: one forward pass over their flattened observations.

        Args:
            obs: Every observation part as ``(n, ...)`` arrays.
            slots: The agents' slots (unused: the network is the same for every agent).
            step: Steps since the reset (unused).

        Returns:
            ``{part: (n, *shape)}`` float32 arrays, clipped to [-1, 1] as ``act`` clips them.
        """
        n = int(np.asarray(slots).shape[0])
        batch = np.concatenate([np.asarray(obs[k], dtype=np.float32).reshape(n, -1) for k in self._obs_keys], axis=1)
        actions = self._predict(batch)
        return {k: actions[:, sl].reshape(n, *self._act_shapes[k]) for k, sl in self._act_layout.items()}

    def _predict(self, batch: np.ndarray) -> np.ndarray:
        """``(n, act_dim)`` actions of ``(n, obs_dim)`` flat observations, clipped to [-1, 1]."""
        n = batch.shape[0]
        if n < _MIN_ROWS:  # pad: BLAS takes another kernel for one or two rows, whose sums round differently
            padded = np.zeros((_MIN_ROWS, batch.shape[1]), dtype=np.float32)
            padded[:n] = batch
            batch = padded
        actions, _ = self.model.predict(batch, deterministic=self.deterministic)
        return np.clip(np.asarray(actions, dtype=np.float32)[:n], -1.0, 1.0)


def load_policy(path: str | Path, env: Any, *, deterministic: bool = True) -> LearnedPolicy:
    """Load a model trained by ``agentsim train`` as a policy for ``env``.

    Args:
        path: The model folder (with ``model.zip`` and ``config.json``) or a ``.zip``.
        env: A ParallelEnv of the model's scenario, built with the model's config.
        deterministic: Act on the mode of the action distribution.

    Returns:
        The policy.

    Raises:
        ValueError: Missing files, another scenario, a damaged model file (``ModelFileError``, naming it), or
            layouts that differ from the model's.
        ImportError: stable-baselines3 is not installed.
    """
    zip_path, config_path = model_files(path)
    meta = _read_config(config_path)
    scenario = env.scenario.name
    if meta["scenario"] != scenario:
        raise ValueError(f"{str(path)!r} was trained on scenario {meta['scenario']!r}, not {scenario!r}")
    model = load_model(zip_path, device="cpu")
    folder = zip_path.parent
    name = folder.name if zip_path.name == "model.zip" else f"{folder.name}/{zip_path.stem}"
    return LearnedPolicy(model, env, deterministic=deterministic, name=name)
