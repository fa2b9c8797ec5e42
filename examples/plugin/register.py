"""Register the beacon scenario, its policy and its strategy from code (the package need not be installed)."""

import agentsim_env
from agentsim_env.policies.registry import make_policy

agentsim_env.register_scenario("beacon", "agentsim_beacon.scenario:Beacon")
agentsim_env.register_policy("to_beacon", "agentsim_beacon.policy:ToBeaconPolicy", scenario="beacon")
agentsim_env.register_strategy("beacon_ring", "agentsim_beacon.strategy:BeaconRing")

env = agentsim_env.make("beacon", n_agents=3, max_steps=60)
policy = make_policy("beacon", env, "to_beacon")
obs, infos = env.reset(seed=0)
arrived = 0
while env.agents:
    obs, rewards, terminations, truncations, infos = env.step(policy.act(obs))
    arrived += sum(int(info["arrived"]) for info in infos.values())
print(f"beacon: {arrived} of 3 agents arrived")
