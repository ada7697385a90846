"""The simulator as a Gymnasium vector environment."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ._rlnav import VecSim


def _spaces(sim: VecSim) -> tuple[spaces.Box, spaces.Box]:
    """One environment's spaces: the task's observation vector (bounded where the task bounds
    a value: lidar clip, bearing, the last command) and the normalised action (linear,
    angular) in [-1, 1]."""
    low, high = sim.obs_bounds()
    obs = spaces.Box(np.array(low, dtype=np.float32), np.array(high, dtype=np.float32), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    return obs, act


def episode_info(stats: dict[str, Any]) -> dict[str, Any]:
    """What one environment's ``info`` holds at the end of an episode: the episode's figures
    as ``rlnav bench`` reports them (``outcome``: success, collision or timeout), and
    ``is_success`` (the key Stable-Baselines3 logs)."""
    info = dict(stats)
    info["is_success"] = stats["outcome"] == "success"
    return info


class RlnavVectorEnv(VectorEnv):
    """``num_envs`` navigation environments stepped together in Rust.

    Autoreset is Gymnasium's ``SAME_STEP`` mode: when an episode ends, ``step`` returns the
    next episode's first observation, and ``infos["final_obs"]`` / ``infos["final_info"]``
    (with their ``_final_obs`` / ``_final_info`` masks) hold the last observation and the
    episode's figures of the one that ended. ``terminated`` (goal reached or collision) and
    ``truncated`` (time limit) are kept apart.

    Observations are written by Rust into one numpy buffer; with ``copy=True`` (the default)
    the caller gets a copy of it, with ``copy=False`` the buffer itself, which the next step
    overwrites.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str = "random-static",
        robot: str | None = None,
        task: str | os.PathLike | None = None,
        num_envs: int = 1,
        seed: int = 0,
        threads: int = 0,
        render_mode: str | None = None,
        copy: bool = True,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: expected None or 'rgb_array', got {render_mode!r}")
        task = os.fspath(task) if task is not None else None
        self.sim = VecSim(os.fspath(scenario), robot, task, int(num_envs), int(seed), int(threads))
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.copy = copy
        self.description = self.sim.describe()
        self.single_observation_space, self.single_action_space = _spaces(self.sim)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n, d = self.num_envs, self.sim.obs_dim
        self._obs = np.zeros((n, d), dtype=np.float32)
        self._final_obs = np.zeros((n, d), dtype=np.float32)
        self._rewards = np.zeros(n, dtype=np.float32)
        self._terminated = np.zeros(n, dtype=np.bool_)
        self._truncated = np.zeros(n, dtype=np.bool_)
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Starts a new episode everywhere; ``seed`` rebuilds the environments from it."""
        if isinstance(seed, (list, tuple)):
            raise ValueError("seed: expected one int for the batch (environment i is seeded from it and i)")
        super().reset(seed=seed)
        self.sim.reset(self._obs, None if seed is None else int(seed))
        self._started = True
        return self._out(self._obs), {}

    def step(self, actions):
        actions = np.ascontiguousarray(actions, dtype=np.float32).reshape(self.num_envs, 2)
        done = self.sim.step(
            actions, self._obs, self._rewards, self._terminated, self._truncated, self._final_obs
        )
        infos: dict[str, Any] = {}
        if done:
            infos = self._final_infos(done)
        return (
            self._out(self._obs),
            self._rewards.copy(),
            self._terminated.copy(),
            self._truncated.copy(),
            infos,
        )

    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.copy() if self.copy else a

    def _final_infos(self, done: list[tuple[int, dict[str, Any]]]) -> dict[str, Any]:
        """The infos of the episodes that ended, laid out as Gymnasium's vector envs do."""
        n = self.num_envs
        mask = np.zeros(n, dtype=np.bool_)
        final_obs = np.full(n, None, dtype=object)
        final_info: dict[str, Any] = {}
        for i, stats in done:
            mask[i] = True
            final_obs[i] = self._final_obs[i].copy()
            for key, value in episode_info(stats).items():
                if key not in final_info:
                    if isinstance(value, bool):
                        final_info[key] = np.zeros(n, dtype=np.bool_)
                    elif isinstance(value, int):
                        final_info[key] = np.zeros(n, dtype=np.int64)
                    elif isinstance(value, float) or value is None:
                        final_info[key] = np.zeros(n, dtype=np.float64)
                    else:
                        final_info[key] = np.full(n, None, dtype=object)
                    final_info["_" + key] = np.zeros(n, dtype=np.bool_)
                final_info[key][i] = np.nan if value is None else value
                final_info["_" + key][i] = True
        return {"final_obs": final_obs, "_final_obs": mask, "final_info": final_info, "_final_info": mask.copy()}

    def render(self):
        """Every environment as an RGB picture (a tuple of ``uint8[h, w, 3]``)."""
        if self.render_mode != "rgb_array":
            return None
        return tuple(self.sim.render(i) for i in range(self.num_envs))

    def close_extras(self, **kwargs):
        self.sim = None


def make_vec(
    scenario: str = "random-static",
    robot: str | None = None,
    task: str | os.PathLike | None = None,
    num_envs: int = 64,
    seed: int = 0,
    threads: int = 0,
    render_mode: str | None = None,
    copy: bool = True,
) -> RlnavVectorEnv:
    """``num_envs`` environments of ``scenario`` (a shipped name, see ``rlnav.scenarios()``,
    or a YAML file) with ``robot`` (name or file; default: the scenario's) and ``task`` (a
    task YAML file; default: configs/task.yaml's values), seeded from ``seed``, stepped on
    ``threads`` worker threads (0: one per core)."""
    return RlnavVectorEnv(scenario, robot, task, num_envs, seed, threads, render_mode, copy)
