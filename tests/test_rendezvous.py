"""The tutorial scenario: its scripted baseline meets, random motion does not, and the tutorial shows the file."""

from __future__ import annotations

from pathlib import Path

import agentsim_env
from agentsim_env.policies.registry import make_policy

ROOT = Path(__file__).resolve().parents[1]


def _met(policy_name: str, seed: int) -> bool:
    env = agentsim_env.make("rendezvous", n_agents=5)
    policy = make_policy("rendezvous", env, policy_name)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    met = False
    while env.agents:
        obs, _, _, _, infos = env.step(policy.act(obs))
        met |= any(i["met"] for i in infos.values())
    return met


def test_meet_policy_meets_and_random_does_not() -> None:
    meet = sum(_met("meet", s) for s in range(10))
    rand = sum(_met("random", s) for s in range(10))
    assert meet >= 9 and rand <= 2, (meet, rand)


def test_tutorial_shows_the_whole_file() -> None:
    doc = (ROOT / "docs" / "new_scenario.md").read_text(encoding="utf-8")
    src = (ROOT / "agentsim_env" / "scenarios" / "rendezvous.py").read_text(encoding="utf-8")
    assert "```python\n" + src + "```" in doc
