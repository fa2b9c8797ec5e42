"""Each scenario as a PettingZoo-style module (as ``pettingzoo.mpe.simple_v3``): ``env``, ``parallel_env`` and
``raw_env``, named like the scenario's ``metadata["name"]``.

Example:
    >>> from agentsim_env.zoo import navigation_v0
    >>> par = navigation_v0.parallel_env(n_agents=4)
"""
