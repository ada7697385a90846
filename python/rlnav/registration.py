"""Gymnasium ids for the shipped scenarios: ``rlnav/RandomStatic-v0`` and so on."""

from __future__ import annotations

import gymnasium as gym

from ._rlnav import scenarios


def env_id(scenario: str) -> str:
    """The Gymnasium id of a shipped scenario: ``random-static`` -> ``rlnav/RandomStatic-v0``."""
    return "rlnav/" + "".join(part[:1].upper() + part[1:] for part in scenario.split("-")) + "-v0"


def register_envs() -> None:
    """Registers every shipped scenario with Gymnasium (``gym.make`` and ``gym.make_vec``
    with ``vectorization_mode="vector_entry_point"`` for the Rust batch)."""
    for name in scenarios():
        eid = env_id(name)
        if eid in gym.registry:
            continue
        gym.register(
            id=eid,
            entry_point="rlnav.env:RlnavEnv",
            vector_entry_point="rlnav.vector:RlnavVectorEnv",
            kwargs={"scenario": name},
            # The task cuts episodes itself (truncated at its max_steps).
            max_episode_steps=None,
            disable_env_checker=False,
        )
