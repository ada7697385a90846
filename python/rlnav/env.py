"""One navigation environment as a :class:`gymnasium.Env`."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np

from ._rlnav import VecSim
from .vector import _spaces, episode_info


class RlnavEnv(gym.Env):
    """One robot navigating to a goal: the observation is the task's vector (lidar, goal,
    velocities, as the task's ``observation`` lists), the action the normalised (linear,
    angular) command in [-1, 1]. ``terminated``: goal reached or collision; ``truncated``:
    the task's time limit. At an episode's end ``info`` holds its figures (``outcome``,
    ``is_success``, ``min_range``, ``path_length``...)."""

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
        task = os.fspath(task) if task is not None else None
        self.sim = VecSim(os.fspath(scenario), robot, task, 1, int(seed), 1)
        self.render_mode = render_mode
        self.render_size = int(render_size)
        self.description = self.sim.describe()
        self.observation_space, self.action_space = _spaces(self.sim)
        d = self.sim.obs_dim
        self._obs = np.zeros((1, d), dtype=np.float32)
        self._final_obs = np.zeros((1, d), dtype=np.float32)
        self._reward = np.zeros(1, dtype=np.float32)
        self._terminated = np.zeros(1, dtype=np.bool_)
        self._truncated = np.zeros(1, dtype=np.bool_)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.sim.reset(self._obs, None if seed is None else int(seed))
        return self._obs[0].copy(), {}

    def step(self, action):
        a = np.ascontiguousarray(action, dtype=np.float32).reshape(1, 2)
        done = self.sim.step(a, self._obs, self._reward, self._terminated, self._truncated, self._final_obs)
        info: dict[str, Any] = {}
        obs = self._obs[0]
        if done:
            # The simulator has already begun the next episode; a single env shows the end of
            # this one and begins the next at reset().
            obs = self._final_obs[0]
            info = episode_info(done[0][1])
        return obs.copy(), float(self._reward[0]), bool(self._terminated[0]), bool(self._truncated[0]), info

    def render(self):
        """The scene as ``uint8[h, w, 3]`` (with ``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        return self.sim.render(0, self.render_size)


def make(
    scenario: str = "random-static",
    robot: str | None = None,
    task: str | os.PathLike | None = None,
    seed: int = 0,
    render_mode: str | None = None,
) -> RlnavEnv:
    """One environment of ``scenario`` with ``robot`` and ``task`` (as :func:`rlnav.make_vec`)."""
    return RlnavEnv(scenario, robot, task, seed, render_mode)
