"""The reward composer every scenario configures.

reward_i = task_weight * task_i
         + group_share * mean(task_j for j in i's group and world, j acting this step)
         - collision_penalty * collided_i
         - energy_weight * energy_i
         - message_cost * messages_sent_i

The group means come from exact fixed-point sums (``task_partials``: each task value rounded to a multiple of
2**-32, |value| <= 2**40), so a group whose members are summed in several parts (``combine_partials``) gets the
same mean, bit for bit, as one sum over all of them. A larger value (a config with huge reward weights) is summed
as a float apart: exact within one process, possibly not in the last bits over shards.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Annotated

import numba as nb
import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Real, config
from agentsim_env.core.threads import RowThreads, light_min_rows

_ONE_THREAD = RowThreads(1)


Weight = Annotated[Real, Field(ge=0.0)]
"""A reward weight, >= 0."""


@config("reward")
class RewardConfig:
    """Weights of the reward terms (all >= 0).

    Attributes:
        task_weight: Weight of the agent's own task reward.
        group_share: Weight of the mean task reward of the agent's group.
        collision_penalty: Subtracted once when the agent collides.
        energy_weight: Multiplies the energy spent this step (scenario units, e.g. J or a speed-squared proxy).
        message_cost: Subtracted per message the agent sent this step.
    """

    task_weight: Weight = 1.0
    group_share: Weight = 0.0
    collision_penalty: Weight = 10.0
    energy_weight: Weight = 0.0
    message_cost: Weight = 0.0


FIXED_POINT_BITS = 32
"""Fraction bits of the group sums: each task value is rounded to a multiple of 2**-32 before it is summed."""
MAX_TASK_VALUE = 2.0**40
"""Largest magnitude of a task value that enters a group sum (about 1.1e12)."""


# Group sums in fixed point. A float sum depends on the order of its additions, so a group split over processes
# (each summing its own members, the parts summed after) would differ from one process in the last bits. Integer
# sums are associative, so every value v is split exactly into hi = floor(v) (int64) and lo = round((v - hi) *
# 2**32) (an int64 in [0, 2**32]); the group's hi and lo words are summed separately, and the total is
# sum(hi) + sum(lo) * 2**-32, whatever the split and the order. The rounding moves a value by at most 2**-33.
# With |v| <= MAX_TASK_VALUE = 2**40 neither word can overflow for groups of up to 2**22 (hi) and 2**31 (lo)
# members; a larger finite value is an error that names it. Non-finite values are counted apart (NaN, +inf, -inf),
# so a group mean over them is what a float sum gives (NaN, or the infinity) and check_finite still names it.
@nb.njit(cache=True, nogil=True)
def _max_key(lo, hi, group, world, mask, n_worlds):  # type: ignore[no-untyped-def]
    # The largest group_keys value among the masked slots [lo, hi) (-1: none).
    top = -1
    for s in range(lo, hi):
        if mask[s]:
            g = group[s]
            top = max(top, (g if g >= 0 else 0) * n_worlds + world[s])
    return top


@nb.njit(cache=True, nogil=True)
def _partials_kernel(lo, hi, task, group, world, mask, n_worlds, bound, hi_w, lo_w, cnt, bad, big):  # type: ignore[no-untyped-def]  # noqa: E501
    # The fixed-point sums of the masked slots [lo, hi) added into this range's arrays (integer sums: ranges may
    # run on different threads and be added in any order). A finite value over the bound is counted and marked
    # in ``big`` (summed as a float apart); returns how many.
    n_big = 0
    for s in range(lo, hi):
        if not mask[s]:
            continue
        g = group[s]
        k = (g if g >= 0 else 0) * n_worlds + world[s]
        v = task[s]
        cnt[k] += 1
        if np.isnan(v):
            bad[0, k] += 1
        elif np.isinf(v):
            bad[1 if v > 0 else 2, k] += 1
        elif abs(v) > bound:
            big[s] = True
            n_big += 1
        else:
            f = np.floor(v)
            hi_w[k] += np.int64(f)
            lo_w[k] += np.int64(np.rint((v - f) * 4294967296.0))
    return n_big


def group_keys(group: np.ndarray, world: np.ndarray, n_worlds: int) -> np.ndarray:
    """Index ``group * n_worlds + world`` of each slot's (world, group) in the partial arrays (group -1 -> 0).

    Group-major, so a group id beyond the configured groups (``assign_group`` takes ids up to ``n_agents - 1``)
    only lengthens the arrays: every part indexes a (world, group) the same way whatever its length.
    """
    g = np.asarray(group)
    return np.where(g >= 0, g, 0).astype(np.int64) * int(n_worlds) + np.asarray(world).astype(np.int64)


def task_partials(
    task: np.ndarray,
    group: np.ndarray,
    world: np.ndarray,
    mask: np.ndarray,
    n_groups: int,
    n_worlds: int,
    threads: RowThreads | None = None,
) -> dict[str, np.ndarray]:
    """One part's group sums of the task values over the slots in ``mask``, in fixed point.

    Args:
        task: Task value per slot ``(S,)``.
        group: Group id per slot (-1: no group; counted in group 0's sums, its own reward takes its own value).
        world: World id per slot.
        mask: The slots this part sums (e.g. acting slots that the part owns).
        n_groups: Groups per world (the arrays hold at least these).
        n_worlds: Worlds B.
        threads: Row threads to sum slot ranges on (the sums do not depend on them).

    Returns:
        ``{"task_hi", "task_lo", "task_count", "task_nan", "task_pinf", "task_ninf"}`` (the fixed-point words,
        the members, the non-finite members): int64 arrays ``(B * G,)`` indexed ``group * B + world``
        (:func:`group_keys`), G = ``n_groups`` or one more than the largest masked group id if that is larger;
        to add up over parts with :func:`combine_partials`.

    A finite value over ``MAX_TASK_VALUE`` in magnitude is summed as a float apart (``task_big``): exact within
    one process, not across parts.
    """
    task = np.ascontiguousarray(task, dtype=np.float64)
    group = np.ascontiguousarray(group, dtype=np.int64)
    world = np.ascontiguousarray(world, dtype=np.int64)
    mask = np.ascontiguousarray(mask, dtype=np.bool_)
    threads = threads or _ONE_THREAD
    n, b = task.shape[0], int(n_worlds)
    size = b * max(int(n_groups), 1)
    light = light_min_rows()
    top = max(threads.run(lambda lo, hi, _: _max_key(lo, hi, group, world, mask, b), n, light))  # -1: none
    size = max(size, top + 1)
    big = np.zeros(n, dtype=np.bool_)
    parts: list[tuple[np.ndarray, ...]] = []

    def sums(lo: int, hi: int, _: int) -> int:
        # each range its own arrays, added after (exact: integer sums)
        out = (
            np.zeros(size, dtype=np.int64),
            np.zeros(size, dtype=np.int64),
            np.zeros(size, dtype=np.int64),
            np.zeros((3, size), dtype=np.int64),
        )
        parts.append(out)
        return int(_partials_kernel(lo, hi, task, group, world, mask, b, MAX_TASK_VALUE, *out, big))

    n_big = sum(threads.run(sums, n, light))  # every range appended its arrays (one at least, even for n = 0)
    hi_w, lo_w, cnt, odd = parts[0]
    for p in parts[1:]:
        hi_w, lo_w, cnt, odd = hi_w + p[0], lo_w + p[1], cnt + p[2], odd + p[3]
    # values beyond the fixed point's range (a config with huge reward weights) are summed as floats apart, in
    # slot order: the sum is then exact only within one process, which a valid config must still be able to run
    big_sum = np.zeros(size)
    if n_big:
        at = np.flatnonzero(big)
        big_sum = np.bincount(group_keys(group[at], world[at], b), weights=task[at], minlength=size)[:size]
    return {
        "task_hi": hi_w,
        "task_lo": lo_w,
        "task_count": cnt,
        "task_nan": odd[0],
        "task_pinf": odd[1],
        "task_ninf": odd[2],
        "task_big": big_sum,
    }


def combine_partials(parts: Iterable[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Add up the partial sums of several parts key by key (integer sums: any order gives the same totals).

    Arrays of one key may differ in length (a part with a higher group id has a longer one): the shorter ones
    count as zero-padded.

    Args:
        parts: Each part's partials (the same keys in every part).

    Returns:
        The totals (fresh arrays); ``{}`` for no parts or parts without partials.
    """
    out: dict[str, np.ndarray] = {}
    for p in parts:
        for k, v in p.items():
            have = out.get(k)
            if have is None:
                out[k] = np.array(v, copy=True)
                continue
            if have.shape[0] < v.shape[0]:
                have = np.concatenate([have, np.zeros(v.shape[0] - have.shape[0], dtype=have.dtype)])
            have[: v.shape[0]] += v
            out[k] = have
    return out


def at_keys(total: np.ndarray, key: np.ndarray) -> np.ndarray:
    """``total[key]`` with keys past the end of ``total`` reading 0 (groups no part had members of)."""
    if key.size and int(key.max()) >= total.shape[0]:
        total = np.concatenate([total, np.zeros(int(key.max()) + 1 - total.shape[0], dtype=total.dtype)])
    return total[key]


def group_means(totals: dict[str, np.ndarray]) -> np.ndarray:
    """Mean task value per (world, group) from combined partials: ``(hi + lo * 2**-32) / max(count, 1)``.

    A group with a NaN member, or with both infinities, has mean NaN; one with one kind of infinity has it.
    """
    total = totals["task_hi"].astype(np.float64) + totals["task_lo"].astype(np.float64) * 2.0**-FIXED_POINT_BITS
    if "task_big" in totals:
        total = total + totals["task_big"]
    mean = total / np.maximum(totals["task_count"], 1).astype(np.float64)
    nan, pinf, ninf = totals["task_nan"] > 0, totals["task_pinf"] > 0, totals["task_ninf"] > 0
    if nan.any() or pinf.any() or ninf.any():
        mean = np.where(pinf, np.inf, np.where(ninf, -np.inf, mean))
        mean[nan | (pinf & ninf)] = np.nan
    return mean


def group_mean(values: np.ndarray, group: np.ndarray, world: np.ndarray, mask: np.ndarray, n_groups: int) -> np.ndarray:
    """Mean of ``values`` over the masked members of each (world, group), broadcast back to every slot.

    Slots with group -1 (no group) get their own value. The sums are the fixed-point ones of
    :func:`task_partials` (one part over every slot).
    """
    if not np.size(values):
        return np.asarray(values, dtype=np.float64).copy()
    n_worlds = int(np.max(world)) + 1
    totals = task_partials(values, group, world, mask, n_groups, n_worlds)
    mean = at_keys(group_means(totals), group_keys(group, world, n_worlds))
    return np.where(np.asarray(group) >= 0, mean, values)


_NONE = np.zeros(0)  # stands in for an absent term (the kernel never reads it)
_NONE_KEY = np.zeros(0, dtype=np.int64)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _compose_kernel(lo, hi, task, group, acting, key, means, collided, energy, sent, w, use, out):  # type: ignore[no-untyped-def]  # noqa: E501
    # Slots [lo, hi) of out. The terms are added in the order of the numpy expression, so the result is
    # bit-identical to it.
    tw, gs, cp, ew, mc = w[0], w[1], w[2], w[3], w[4]
    use_group, use_coll, use_energy, use_sent = use
    for s in range(lo, hi):
        if not acting[s]:
            out[s] = 0.0
            continue
        r = tw * task[s]
        if use_group:
            g = means[key[s]] if group[s] >= 0 else task[s]
            r = r + gs * g
        if use_coll:
            r = r - cp * collided[s]
        if use_energy:
            r = r - ew * energy[s]
        if use_sent:
            r = r - mc * sent[s]
        out[s] = r
    return out


def compose_rewards(
    cfg: RewardConfig,
    task: np.ndarray,
    *,
    group: np.ndarray,
    world: np.ndarray,
    acting: np.ndarray,
    n_groups: int,
    collided: np.ndarray | None = None,
    energy: np.ndarray | None = None,
    messages_sent: np.ndarray | None = None,
    totals: dict[str, np.ndarray] | None = None,
    n_worlds: int | None = None,
    threads: RowThreads | None = None,
) -> np.ndarray:
    """Combine the terms into one reward per slot (zero for slots that were not acting).

    One numba pass (the composition runs every step); the tests hold the numpy statement of the same
    formula.

    Args:
        cfg: The weights.
        task: Task reward per slot ``(S,)``.
        group: Group id per slot.
        world: World id per slot.
        acting: Slots that acted this step (alive at its start).
        n_groups: Number of groups per world.
        collided: Slots that collided this step.
        energy: Energy spent this step per slot.
        messages_sent: Messages sent this step per slot.
        totals: The group sums (:func:`task_partials` of every part, combined) when the slots are split over
            parts; ``None``: summed here over every acting slot.
        n_worlds: Worlds B, the stride of the group sums (``None``: one more than the largest world id).
        threads: Row threads to compose slot ranges on (the rewards do not depend on them).

    Returns:
        Rewards ``(S,)`` as float64 (a fresh array).
    """
    use = (
        bool(cfg.group_share) and task.shape[0] > 0,
        collided is not None and bool(cfg.collision_penalty),
        energy is not None and bool(cfg.energy_weight),
        messages_sent is not None and bool(cfg.message_cost),
    )
    w = (
        float(cfg.task_weight),
        float(cfg.group_share),
        float(cfg.collision_penalty),
        float(cfg.energy_weight),
        float(cfg.message_cost),
    )
    task = np.asarray(task, dtype=np.float64)
    acting = np.asarray(acting, dtype=np.bool_)
    group = np.asarray(group)
    key, means = _NONE_KEY, _NONE
    if use[0]:
        b = int(np.max(world)) + 1 if n_worlds is None else int(n_worlds)
        key = group_keys(group, world, b)
        if totals is None:
            totals = task_partials(task, group, world, acting, n_groups, b, threads)
        means = group_means(totals)
        if int(key.max()) >= means.shape[0]:  # a group no part had acting members of (read by no acting slot)
            means = np.concatenate([means, np.zeros(int(key.max()) + 1 - means.shape[0])])
    args = (
        task,
        group,
        acting,
        key,
        means,
        _NONE if collided is None else np.asarray(collided, dtype=np.float64),
        _NONE if energy is None else np.asarray(energy, dtype=np.float64),
        _NONE if messages_sent is None else np.asarray(messages_sent),
        w,
        use,
    )
    out = np.empty(task.shape[0])
    (threads or _ONE_THREAD).run(lambda lo, hi, _: _compose_kernel(lo, hi, *args, out), task.shape[0], light_min_rows())
    return out
