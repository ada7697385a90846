"""One navigation environment as a :class:`gymnasium.Env`."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np

from .vector import RlnavVectorEnv


class RlnavEnv(gym.Env):
    """One robot navigating to a goal: the observation is the task's vector (lidar, goal,
    velocities, as the task's ``observation`` lists), the action the normalised (linear,
    angular) command in [-1, 1]. ``terminated``: goal reached or collision; ``truncated``:
    the task's time limit. At an episode's end ``info`` holds its figures (``outcome``,
    ``is_success``, ``min_range``, ``path_length``...).

    It is a batch of one (:class:`rlnav.RlnavVectorEnv`) that shows the ended episode's last
    observation instead of the next episode's first, which ``reset()`` then begins."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str = "random-static",
        robot: str | None = None,
        task: str | os.PathLike | None = None,
        seed: int = 0,
        render_mode: str | None = None,
        render_size: int = 400,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: expected None or 'rgb_array', got {render_mode!r}")
        self.batch = RlnavVectorEnv(scenario, robot, task, num_envs=1, seed=seed, threads=1)
        self.render_mode = render_mode
        self.render_size = int(render_size)
        self.description = self.batch.description
        self.observation_space = self.batch.single_observation_space
        self.action_space = self.batch.single_action_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, _ = self.batch.reset(seed=seed)
        return obs[0], {}

    def step(self, action):
        obs, reward, terminated, truncated, infos = self.batch.step(np.asarray(action, dtype=np.float32)[None])
        if not infos:
            return obs[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]), {}
        info = {k: v[0] for k, v in infos["final_info"].items() if not k.startswith("_")}
        return infos["final_obs"][0], float(reward[0]), bool(terminated[0]), bool(truncated[0]), info

    def render(self):
        """The scene as ``uint8[h, w, 3]`` (with ``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        return self.batch.sim.render(0, self.render_size)


def make(
    scenario: str = "random-static",
    robot: str | None = None,
    task: str | os.PathLike | None = None,
    seed: int = 0,
    render_mode: str | None = None,
) -> RlnavEnv:
    """One environment of ``scenario`` with ``robot`` and ``task`` (as :func:`rlnav.make_vec`)."""
    return RlnavEnv(scenario, robot, task, seed, render_mode)
