"""The ``relay`` scenario under PettingZoo's constructor names (as ``pettingzoo.mpe.simple_v3``).

Example:
    >>> from agentsim_env.zoo import relay_v0
    >>> par = relay_v0.parallel_env(render_mode="rgb_array")
    >>> aec = relay_v0.env()  # raw_env(): the AEC env without PettingZoo's order checks
"""

from agentsim_env.env.constructors import scenario_constructors

env, parallel_env, raw_env = scenario_constructors("relay")

__all__ = ["env", "parallel_env", "raw_env"]
