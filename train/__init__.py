"""Training entry points (stable-baselines3 PPO with parameter sharing over the batched env)."""
