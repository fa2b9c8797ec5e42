"""Batch runs of the UAV sensor-release case study: (zone file, strategy, seed) -> metrics and sensor rows.

One run builds a fresh ``uav_release`` env for the zone file and the config overrides, flies the strategy's
scripted policy until the mission ends (``mission.fly_mission``, which also accounts for the mission costs
of domain reference 2.5), then evaluates the landed sensors with ``wsn.evaluate_deployment``, their
intended landing points as targets. A run's metrics (``runs.csv`` columns after ``zones, strategy, seed``):

======================== ========================================================================
key                      meaning
======================== ========================================================================
completed                1 when the mission ended before ``max_steps`` or the policy reported its work
                         done (0: cut off by the time limit)
steps, mission_time_s    steps taken and ``steps * dt``
energy_j                 UAV propulsion energy over the fleet (rotary-wing model), J
energy_fraction          ``energy_j`` / (``n_uavs`` x ``battery_j``), the fleet's battery used
path_length_m            3D distance flown by the fleet, summed from per-step positions
sensors_required         sensors the zone file asks for
payload_total            sensors carried (``n_uavs`` x ``payload``)
sensors_released         sensors released; ``sensors_landed`` of them are on the ground at the end
delivered_fraction       ``min(sensors_landed / sensors_required, 1)``
messages_sent            agent messages (bus AGENT / GROUP, overlay floods started)
messages_dropped         agent bus messages lost (bandwidth, range, loss, offline receiver)
near_misses              UAV pairs closer than ``mission.NEAR_MISS_M`` (3D), once per pair per run
collisions               UAVs lost to collisions
<WSN metrics>            every key of ``evaluate_deployment`` (zone weights from the zone file unless
                         ``wsn.zone_weights`` is set)
coverage_weighted_vs_oracle, lcc_fraction_vs_oracle, fnd_vs_oracle
                         the run's value over the B8 teleport reference of the same zone file
======================== ========================================================================

The B8 teleport reference (``TELEPORT``) is evaluated without flying: the oracle layout
(``uav_outcome.oracle_points``: every zone's low-discrepancy points) placed exactly, zero landing error and
no flight cost. It is computed once per zone file and reported for every seed (it has no randomness), so
scores can be normalised by it (domain reference 5.4).

Everything is deterministic: a run depends only on the zone file, the overrides, the strategy and the seed.

With ``record_env`` (``agentsim evaluate --record run.db`` passes ``agentsim_env.recorder.record`` to a store),
every flown mission is recorded as one run labelled ``zones=<label> strategy=<name> seed=<seed>``
(``mission_label``); ``RunResult.store_run`` is its run id. The teleport reference is not flown and not recorded.
This package sits beside the recorder (same layer), so it is handed the recording function, never imports it.

Strategy names and policies come from the ``strategies`` registry (``agentsim_env.policies.registry``).
A strategy token that is a path is a trained model folder (``model.zip`` and ``config.json`` naming scenario
``uav_release``, checked up front): it is named by its folder name in the tables, and its missions are flown
in an env built with the model's ``env`` config merged over the run's overrides (so a model trained in
autopilot mode flies in autopilot mode; its ``zones`` key, if any, is dropped: ``--zones`` chooses them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.uav.evaluation.mission import MISSION_KEYS, fly_mission, sensor_rows
from agentsim_env.uav.evaluation.strategies import (
    current_name,
    is_model_token,
    model_env,
    model_label,
    policy_factory,
    strategy_names,
)
from agentsim_env.uav.outcome import oracle_points
from agentsim_env.uav.wsn.evaluate import WsnConfig, evaluate_deployment
from agentsim_env.uav.zones import ZoneSet, default_zones_path, load_zones, tiny_zones_path

__all__ = [
    "SCENARIO",
    "TELEPORT",
    "GridResult",
    "RunResult",
    "ZoneSource",
    "available_strategies",
    "mission_label",
    "resolve_strategies",
    "resolve_zones",
    "run_grid",
    "run_one",
    "strategy_labels",
    "teleport_reference",
]

SCENARIO = "uav_release"
#: Name of the B8 teleport reference row (not a flown strategy).
TELEPORT = "B8_teleport"
_NAMED_ZONES = {"default": default_zones_path, "tiny": tiny_zones_path}
# Values the runs are normalised by, and the reference's key they divide by.
_VS_ORACLE = {"coverage_weighted": "coverage_weighted", "lcc_fraction": "lcc_fraction", "fnd": "fnd"}


@dataclass(frozen=True)
class ZoneSource:
    """A zone file to evaluate on.

    Attributes:
        label: Short name used in file names, CSV rows and tables (``default``, ``tiny`` or the file stem).
        path: The JSON file.
        zones: Its validated zones.
    """

    label: str
    path: Path
    zones: ZoneSet


@dataclass
class RunResult:
    """Outcome of one (zone file, strategy, seed) run.

    Attributes:
        zones: Zone file label.
        strategy: Strategy name (or ``TELEPORT``).
        seed: Reset seed.
        metrics: Mission costs and WSN metrics (see the module docstring), floats.
        sensors: One dict per released sensor with the ``report.SENSOR_COLUMNS`` keys.
        store_run: The run id of the recorded mission (``run_one``'s ``record_env``; None: not recorded).
    """

    zones: str
    strategy: str
    seed: int
    metrics: dict[str, float]
    sensors: list[dict[str, Any]] = field(default_factory=list)
    store_run: int | None = None

    def row(self) -> dict[str, Any]:
        """``zones, strategy, seed`` followed by every metric (a ``runs.csv`` row)."""
        return {"zones": self.zones, "strategy": self.strategy, "seed": self.seed, **self.metrics}


@dataclass
class GridResult:
    """Every run of a grid, in run order (zone file, then strategy with the reference first, then seed).

    Attributes:
        runs: The runs.
        sources: The zone files, in the order given.
        strategies: Flown strategies, in the order given (``TELEPORT`` not included).
        seeds: The seeds.
        overrides: The scenario config overrides used.
    """

    runs: list[RunResult]
    sources: list[ZoneSource]
    strategies: list[str]
    seeds: list[int]
    overrides: dict[str, Any]


# ------------------------------------------------------------------------------------------ inputs
def resolve_zones(specs: Sequence[str | Path]) -> list[ZoneSource]:
    """Load zone files given as ``"default"``, ``"tiny"`` or JSON paths; labels are made unique.

    Args:
        specs: Names or paths (at least one).

    Returns:
        One ``ZoneSource`` per spec, in order.

    Raises:
        ValueError: On an empty list, a missing or unreadable file or an invalid zone file (the message names
            the value and the allowed forms).
    """
    if not specs:
        raise ValueError("zones must name at least one zone file: 'default', 'tiny' or a JSON path")
    out: list[ZoneSource] = []
    seen: dict[str, int] = {}
    for spec in specs:
        name = str(spec)
        path = _NAMED_ZONES[name]() if name in _NAMED_ZONES else Path(name)
        label = name if name in _NAMED_ZONES else path.stem
        if not path.is_file():
            raise ValueError(f"zones file {name!r} not found; use 'default', 'tiny' or the path of a JSON zone file")
        try:
            zones = load_zones(path)
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"zones file {name!r} cannot be read: {exc}") from exc
        except ValueError as exc:
            raise ValueError(f"bad zones file {name!r}: {exc}") from exc
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:  # two files with the same stem
            label = f"{label}_{seen[label]}"
        out.append(ZoneSource(label, path, zones))
    return out


def available_strategies() -> list[str]:
    """The scripted release strategies registered for ``uav_release`` (registry order)."""
    return strategy_names(SCENARIO)


def resolve_strategies(names: Iterable[str]) -> list[str]:
    """Expand ``"all"`` (every registered strategy, by name) and check names.

    The strategy named ``TELEPORT`` is flown like every other one (its table label is ``TELEPORT + "_flown"``);
    the ``TELEPORT`` reference row (placed, not flown) is always added by ``run_grid``. A deprecated former
    name is replaced by its current name (with a ``DeprecationWarning``).

    Args:
        names: Strategy names, trained model folders (paths), or ``["all"]``.

    Returns:
        The flown strategies (names, and model folders as given), in the order given, without duplicates.

    Raises:
        ValueError: On an unknown name (the message lists the allowed ones), a model folder without
            ``model.zip`` / ``config.json`` or trained on another scenario, or an empty selection.
    """
    allowed = available_strategies()
    out: list[str] = []
    for name in names:
        picked = sorted(allowed) if name == "all" else [name]  # B0 ... B8, whatever the registry order
        for n in picked:
            if n not in allowed and not is_model_token(n):
                n = current_name(SCENARIO, n)
            if n not in allowed and is_model_token(n):
                model_env(n, SCENARIO)  # validates the folder
                if n not in out:
                    out.append(n)
                continue
            if n not in allowed:
                names = ", ".join(allowed)
                raise ValueError(
                    f"unknown strategy {n!r}; allowed: 'all', {names} or a trained model folder (a path holding "
                    f"model.zip and config.json) (the {TELEPORT} reference, not flown, is always added)"
                )
            if n not in out:
                out.append(n)
    if not out:
        raise ValueError(f"strategies must name at least one of: 'all', {', '.join(allowed)}")
    return out


def _is_model(strategy: str) -> bool:
    """Whether a resolved strategy is a trained model folder (not a registered name)."""
    return is_model_token(strategy) and strategy not in available_strategies()


def strategy_labels(strategies: Sequence[str]) -> list[str]:
    """Table names of resolved strategies: registered names as they are, model folders by folder name.

    Labels are made unique (``name_2`` ...) when folder names repeat or match a registered name; the flown
    ``TELEPORT`` strategy is ``TELEPORT + "_flown"`` (``TELEPORT`` names the reference row, placed not flown).
    """
    out: list[str] = []
    for s in strategies:
        label = model_label(s) if _is_model(s) else s
        if label == TELEPORT:
            label = f"{TELEPORT}_flown"
        base, i = label, 1
        while label in out or label == TELEPORT:
            i += 1
            label = f"{base}_{i}"
        out.append(label)
    return out


def _strategy_overrides(strategy: str, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The run's overrides, with a trained model's env config merged over them (its ``zones`` dropped)."""
    out = dict(overrides)
    if _is_model(strategy):
        env = model_env(strategy, SCENARIO)
        env.pop("zones", None)
        out.update(env)
    return out


def _make_env(source: ZoneSource, overrides: Mapping[str, Any]) -> Any:
    """A fresh ``uav_release`` env on ``source`` with the overrides (``zones`` may not be overridden)."""
    import agentsim_env

    if "zones" in overrides:
        raise ValueError("config override 'zones' is not allowed here; choose zone files with --zones")
    return agentsim_env.make(SCENARIO, zones=source.zones, **dict(overrides))


def _wsn_config(config: Any, zones: ZoneSet) -> WsnConfig:
    """The scenario's WSN settings, with the zone file's weights unless weights are set explicitly."""
    wsn: WsnConfig = config.wsn
    return wsn if wsn.zone_weights is not None else replace(wsn, zone_weights=tuple(zones.weights().tolist()))


def _evaluate(zones: ZoneSet, wsn: WsnConfig, land: np.ndarray, zone_of: np.ndarray, targets: np.ndarray) -> dict:
    profiles = [z.radial_profile() for z in zones.zones]
    return evaluate_deployment(land, zone_of, zones.centres(), zones.radii(), profiles, wsn, targets)


# ------------------------------------------------------------------------------------------ runs
def mission_label(zones: str, strategy: str, seed: int) -> str:
    """The ``runs.label`` of a recorded mission: ``zones=<label> strategy=<name> seed=<seed>``."""
    return f"zones={zones} strategy={strategy} seed={seed}"


def run_one(
    source: ZoneSource,
    strategy: str,
    seed: int,
    overrides: Mapping[str, Any] | None = None,
    reference: Mapping[str, float] | None = None,
    record_env: Callable[[Any, str], Any] | None = None,
    label: str | None = None,
) -> RunResult:
    """Fly one strategy on one zone file with one seed and evaluate the deployment.

    Args:
        source: The zone file.
        strategy: A registered ``uav_release`` baseline name or a trained model folder (module docstring).
        seed: Reset seed of the env and the policy.
        overrides: Scenario config values (not ``zones``).
        reference: The teleport reference's metrics, for the ``*_vs_oracle`` keys (NaN without it).
        record_env: Records the mission: called with the env and the mission's ``mission_label``, it returns the
            env to fly, whose ``recorder`` (``run``, ``error``, ``path``, ``finish``) writes it, e.g.
            ``lambda env, label: agentsim_env.recorder.record(env, "run.db", label=label)``.
        label: The strategy's name in the result (default: ``strategy_labels([strategy])[0]``).

    Returns:
        The run's metrics and sensor rows.

    Raises:
        ValueError: The recording failed during the mission (a write error stops a recorder without stopping
            its env; the mission's rows in the store would be incomplete), or ``record_env`` raised one
            (``StoreError``: the store cannot be opened).
    """
    name = label if label is not None else strategy_labels([strategy])[0]
    env = _make_env(source, _strategy_overrides(strategy, overrides or {}))
    label = mission_label(source.label, name, seed)
    rec = None
    if record_env is not None:
        try:
            env = record_env(env, label)
        except BaseException:
            env.close()
            raise
        rec = env.recorder
    try:
        metrics = fly_mission(env, policy_factory()(SCENARIO, env, strategy), seed)
        if rec is not None and rec.error is not None:
            raise ValueError(f"{rec.path}: recording the mission {label} failed ({rec.error})")
        ps = env.world.payloads.objects
        landed = ps.get("landed") & (ps.get("world") == 0)
        wsn = _wsn_config(env.scenario.config, source.zones)
        xy, zone, target = ps.get("land_xy")[landed], ps.get("zone")[landed], ps.get("target_xy")[landed]
        metrics.update(_evaluate(source.zones, wsn, xy, zone, target))
        metrics.update(_vs_oracle(metrics, reference))
        head = {"zones": source.label, "strategy": name, "seed": seed}
        store_run = None if rec is None else rec.run
        result = RunResult(source.label, name, seed, metrics, sensor_rows(ps, head), store_run)
    except BaseException:
        if rec is not None:
            rec.finish("incomplete")
        raise
    finally:
        env.close()  # a recorded run still open is marked complete
    return result


def _vs_oracle(metrics: Mapping[str, float], reference: Mapping[str, float] | None) -> dict[str, float]:
    """``<key>_vs_oracle`` = run value / reference value (NaN without a usable reference)."""
    out = {}
    for key, ref_key in _VS_ORACLE.items():
        ref = math.nan if reference is None else float(reference.get(ref_key, math.nan))
        ok = math.isfinite(ref) and ref > 0.0
        out[f"{key}_vs_oracle"] = float(metrics[key]) / ref if ok else math.nan
    return out


def teleport_reference(source: ZoneSource, overrides: Mapping[str, Any] | None = None) -> RunResult:
    """Evaluate the B8 oracle layout placed exactly: zero landing error, no flight (seed 0).

    Args:
        source: The zone file.
        overrides: Scenario config values; only the WSN settings, fleet size and battery matter.

    Returns:
        A ``RunResult`` named ``TELEPORT`` with the same keys as a flown run.
    """
    env = _make_env(source, overrides or {})
    cfg, zones = env.scenario.config, source.zones
    env.close()
    pts = oracle_points(zones)
    zone_of = np.concatenate([np.full(z.n_sensors, k) for k, z in enumerate(zones.zones)])
    n = float(pts.shape[0])
    metrics = dict.fromkeys(MISSION_KEYS, 0.0)  # no flight, no messages
    metrics.update(
        completed=1.0,
        sensors_required=float(zones.n_sensors),
        sensors_released=n,
        sensors_landed=n,
        payload_total=float(cfg.n_uavs * cfg.payload),
        delivered_fraction=1.0,
    )
    metrics.update(_evaluate(zones, _wsn_config(cfg, zones), pts, zone_of, pts))
    metrics.update(_vs_oracle(metrics, metrics))
    unreleased = dict.fromkeys(("t_release", "x_rel", "y_rel", "z_rel", "vx_rel", "vy_rel"), math.nan)
    head = {"zones": source.label, "strategy": TELEPORT, "seed": 0}
    sensors = [
        {
            **head,
            "sensor_id": i,
            "uav_id": -1,
            "zone_id": int(zone_of[i]),
            **unreleased,
            "x_target": float(x),
            "y_target": float(y),
            "x_land": float(x),
            "y_land": float(y),
            "t_land": 0.0,
        }
        for i, (x, y) in enumerate(pts)
    ]
    return RunResult(source.label, TELEPORT, 0, metrics, sensors)


def run_grid(
    zone_files: Sequence[str | Path],
    strategies: Sequence[str],
    seeds: Sequence[int],
    config_overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    record_env: Callable[[Any, str], Any] | None = None,
) -> GridResult:
    """Run every (zone file, strategy, seed), plus the teleport reference of each zone file.

    Inputs are validated (zone files loaded, strategies checked, one env built per zone file) before the
    first run, so a bad value fails fast.

    Args:
        zone_files: ``"default"``, ``"tiny"`` or JSON paths.
        strategies: Strategy names, trained model folders, or ``["all"]``.
        seeds: Reset seeds (at least one).
        config_overrides: Scenario config values applied to every run (not ``zones``).
        progress: Show a tqdm progress bar (on stderr).
        record_env: Records every flown mission (one run each; see ``run_one``).

    Returns:
        Every run, the reference rows included (one per seed, identical).
    """
    sources = resolve_zones(zone_files)
    names = resolve_strategies(strategies)
    labels = strategy_labels(names)
    seed_list = [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("seeds must hold at least one seed")
    overrides = dict(config_overrides or {})
    refs = {src.label: teleport_reference(src, overrides) for src in sources}  # also validates the overrides
    for name in names:  # a model's env config must build on every zone file
        if _is_model(name):
            for src in sources:
                _make_env(src, _strategy_overrides(name, overrides)).close()
    jobs = [(src, name, seed) for src in sources for name in names for seed in seed_list]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(jobs), desc="evaluate", unit="run")
    runs: list[RunResult] = []
    try:
        for src in sources:
            ref = refs[src.label]
            for s in seed_list:  # the reference has no randomness: one evaluation, reported per seed
                runs.append(
                    RunResult(src.label, TELEPORT, s, dict(ref.metrics), [{**r, "seed": s} for r in ref.sensors])
                )
            for name, lab in zip(names, labels, strict=True):
                for seed in seed_list:
                    if bar is not None:
                        bar.set_postfix_str(f"{src.label} {lab} seed {seed}")
                    runs.append(run_one(src, name, seed, overrides, ref.metrics, record_env=record_env, label=lab))
                    if bar is not None:
                        bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return GridResult(runs, sources, labels, seed_list, overrides)
