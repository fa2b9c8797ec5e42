"""What a ``relay`` policy says: its comm traffic over evaluation episodes, and whether the payload encodes the target.

:func:`record_comm_traffic` rolls a policy out in the flat ``relay`` env (one episode per seed) and keeps, per
step and agent, the role (scout or not), the channel its ``comm`` action chose, whether a message actually left
(``world.comms.sent``), the payload and the scout's target vector (target minus the scout's position, in
metres). :func:`plot_comm_traffic` draws one PNG of four panels:

1. messages sent per live agent and step, scouts vs non-scouts (mean over the episodes);
2. the channel each role chose (share of its actions);
3. every payload value the scouts sent against the target vector component it correlates with best;
4. the target vector decoded linearly (least squares) from the whole payload against the true one, with the
   R^2 of that decoding (1: the payload encodes the target linearly, 0: nothing of it can be read linearly).

The policy is a stable-baselines3 model (anything with ``predict(obs, deterministic=True)``) or a plain
function ``(n, obs_dim) array -> (n, act_dim) array``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CommTraffic", "plot_comm_traffic", "record_comm_traffic"]

PolicyFn = Callable[[np.ndarray], np.ndarray]


@dataclass
class CommTraffic:
    """Per-step records of the episodes (one row per live agent and step).

    Attributes:
        step: Step index within its episode.
        episode: Episode index (position in the seed list).
        scout: Whether the agent is its group's scout.
        channel: Channel index chosen by the action (``comms.stack.CHANNELS``).
        sent: Messages that actually left the agent this step.
        payload: ``(rows, D)`` payload of the action (as sent when ``sent`` > 0).
        target: ``(rows, 2)`` the agent's group target minus the agent's position (metres), before the step.
        max_steps: The config's episode limit.
    """

    step: np.ndarray
    episode: np.ndarray
    scout: np.ndarray
    channel: np.ndarray
    sent: np.ndarray
    payload: np.ndarray
    target: np.ndarray
    max_steps: int

    def decode(self) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares linear decoding of the scouts' target vectors from the payloads they sent.

        Returns:
            ``(true, decoded)`` target vectors, ``(m, 2)`` each, of the ``m`` scout messages (``decoded`` is all
            ``nan`` with fewer than ``D + 2`` messages).
        """
        m = self.scout & (self.sent > 0)
        x, y = self.payload[m], self.target[m]
        if len(x) < x.shape[1] + 2:
            return y, np.full_like(y, np.nan)
        a = np.column_stack([x, np.ones(len(x))])
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        return y, a @ coef

    def decoding_r2(self) -> float:
        """R^2 of the scouts' target vector linearly decoded (least squares) from the payloads they sent.

        Returns:
            The R^2 over both components (``nan`` with fewer than ``D + 2`` scout messages).
        """
        y, fit = self.decode()
        if np.isnan(fit).any():
            return float("nan")
        res = ((y - fit) ** 2).sum()
        tot = ((y - y.mean(axis=0)) ** 2).sum()
        return float(1.0 - res / max(tot, 1e-12))


def _policy_fn(policy: Any) -> PolicyFn:
    if hasattr(policy, "predict"):
        return lambda obs: np.asarray(policy.predict(obs, deterministic=True)[0])
    if callable(policy):
        return policy  # type: ignore[no-any-return]
    raise TypeError(f"policy must have predict() or be callable, got {type(policy).__name__}")


def record_comm_traffic(policy: Any, scenario_config: Mapping[str, Any], seeds: Iterable[int]) -> CommTraffic:
    """Roll ``policy`` out in the flat ``relay`` env, one episode per seed, and record its comm traffic.

    Args:
        policy: A model with ``predict`` (deterministic actions are used) or a function of the stacked flat
            observations of the live agents returning their flat actions.
        scenario_config: ``relay`` config keys, as ``agentsim_env.make("relay", **config)`` takes them.
        seeds: Reset seeds.

    Returns:
        The records.
    """
    import agentsim_env
    from agentsim_env.comms.stack import COMM_HEADER, N_CHANNELS

    act = _policy_fn(policy)
    env = agentsim_env.make("relay", obs_format="flat", action_format="flat", **dict(scenario_config))
    cfg = env.scenario.config
    shape = env.action_space(env.possible_agents[0]).shape
    assert shape is not None  # a flat Box
    motion = int(shape[0]) - cfg.comms.action_dim
    index = {a: i for i, a in enumerate(env.possible_agents)}
    cols: dict[str, list[Any]] = {k: [] for k in ("step", "episode", "scout", "channel", "sent", "payload", "target")}
    for e, seed in enumerate(seeds):
        obs, _ = env.reset(seed=int(seed))
        t = 0
        while env.agents:
            names = list(obs)
            slots = np.array([index[a] for a in names])
            a = np.clip(act(np.stack([obs[n] for n in names])), -1.0, 1.0)
            world = env.world
            target = world.task.target[slots] - world.state.pos[slots, :2]
            scout = world.task.scout[slots].copy()
            obs, _, _, _, _ = env.step({n: a[i] for i, n in enumerate(names)})
            assert world.comms is not None
            comm = a[:, motion:]
            cols["step"].append(np.full(len(names), t))
            cols["episode"].append(np.full(len(names), e))
            cols["scout"].append(scout)
            cols["channel"].append(np.minimum(((comm[:, 0] + 1.0) * (N_CHANNELS / 2.0)).astype(int), N_CHANNELS - 1))
            cols["sent"].append(world.comms.sent[slots].copy())
            cols["payload"].append(comm[:, COMM_HEADER:])
            cols["target"].append(target)
            t += 1
    out = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    d = cfg.comms.payload_dim
    return CommTraffic(
        out["step"].astype(int),
        out["episode"].astype(int),
        out["scout"].astype(bool),
        out["channel"].astype(int),
        out["sent"].astype(int),
        out["payload"].reshape(-1, d),
        out["target"].reshape(-1, 2),
        int(cfg.max_steps),
    )


def plot_comm_traffic(
    policy: Any,
    scenario_config: Mapping[str, Any],
    seeds: Iterable[int],
    path: str | Path,
    *,
    title: str = "",
) -> Path:
    """Record the comm traffic of ``policy`` (see :func:`record_comm_traffic`) and draw it to a PNG.

    Args:
        policy: A model with ``predict`` or a flat-observation -> flat-action function.
        scenario_config: ``relay`` config keys.
        seeds: Reset seeds, one episode each.
        path: PNG to write (its folder is created).
        title: Figure title.

    Returns:
        The PNG path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agentsim_env.comms.stack import CHANNELS

    tr = record_comm_traffic(policy, scenario_config, seeds)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 4, figsize=(19, 4.4), dpi=110)
    ax = axes[0]
    steps = np.arange(int(tr.step.max()) + 1 if tr.step.size else 1)
    for role, mask, colour in (("scouts", tr.scout, "tab:orange"), ("non-scouts", ~tr.scout, "tab:blue")):
        live = np.bincount(tr.step[mask], minlength=steps.size)
        sent = np.bincount(tr.step[mask], weights=tr.sent[mask], minlength=steps.size)
        rate = np.where(live > 0, sent / np.maximum(live, 1), np.nan)
        ax.plot(steps, rate, color=colour, lw=1.4, label=f"{role} ({sent.sum():.0f} messages)")
    ax.set(
        xlabel="step",
        ylabel="messages sent per live agent",
        ylim=(-0.05, 1.05),
        title="messages per step (mean over episodes)",
    )
    ax.legend(fontsize=8)
    ax = axes[1]
    x = np.arange(len(CHANNELS))
    for k, (role, mask, colour) in enumerate(
        (("scouts", tr.scout, "tab:orange"), ("non-scouts", ~tr.scout, "tab:blue"))
    ):
        share = np.bincount(tr.channel[mask], minlength=len(CHANNELS)) / max(int(mask.sum()), 1)
        ax.bar(x + (k - 0.5) * 0.38, share, width=0.38, color=colour, label=role)
    ax.set_xticks(x, CHANNELS)
    ax.set(ylabel="share of actions", title="channel chosen")
    ax.legend(fontsize=8)
    ax = axes[2]
    m = tr.scout & (tr.sent > 0)
    pay, tgt = tr.payload[m], tr.target[m]
    if len(pay) > 2:
        for q in range(pay.shape[1]):
            c = [abs(np.corrcoef(pay[:, q], tgt[:, j])[0, 1]) if pay[:, q].std() > 0 else 0.0 for j in range(2)]
            j = int(np.nanargmax(c))
            ax.scatter(
                tgt[:, j],
                pay[:, q],
                s=4,
                alpha=0.35,
                label=f"payload[{q}] vs target {'xy'[j]} (|r| = {np.nan_to_num(c[j]):.2f})",
            )
        ax.legend(fontsize=7, markerscale=3)
    ax.set(
        xlabel="scout's target vector component (m)",
        ylabel="payload value sent",
        title="scouts' payload values vs their target",
    )
    ax = axes[3]
    true, fit = tr.decode()
    for j, colour in enumerate(("tab:purple", "tab:green")):
        ax.scatter(true[:, j], fit[:, j], s=4, alpha=0.35, color=colour, label=f"target {'xy'[j]}")
    if len(true):
        lim = float(np.abs(true).max()) * 1.05 + 1e-9
        ax.plot([-lim, lim], [-lim, lim], color="grey", lw=0.8, ls="--")
    ax.legend(fontsize=8, markerscale=3)
    ax.set(
        xlabel="scout's target vector (m)",
        ylabel="linearly decoded from the payload (m)",
        title=f"target decoded from the payload (R$^2$ = {tr.decoding_r2():.2f})",
    )
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
