"""``env.render()`` without a render mode warns (as PettingZoo's and Gymnasium's envs do), once per env."""

from __future__ import annotations

import warnings

import agentsim_env


def test_render_without_a_mode_warns_once() -> None:
    env = agentsim_env.make("navigation", n_agents=2, max_steps=3)
    env.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert env.render() is None
        assert env.render() is None
    texts = [str(w.message) for w in caught]
    assert len(texts) == 1, texts
    assert "render_mode" in texts[0] and "rgb_array" in texts[0]
    env.close()


def test_render_with_a_mode_does_not_warn() -> None:
    env = agentsim_env.make("navigation", n_agents=2, max_steps=3, render_mode="rgb_array")
    env.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = env.render()
    assert frame is not None and frame.ndim == 3
    env.close()
