"""Stable-Baselines3 on the Rust batch: a :class:`stable_baselines3.common.vec_env.VecEnv`
over :class:`rlnav.RlnavVectorEnv` (SB3 has its own vector-env interface, not Gymnasium's)."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from .vector import RlnavVectorEnv


class Sb3VecEnv(VecEnv):
    """SB3's view of an rlnav batch. At an episode's end the env's info holds
    ``terminal_observation``, ``TimeLimit.truncated``, ``episode`` (``r``, ``l``, ``t``, as
    SB3's Monitor writes it, so ``ep_rew_mean`` is logged), ``is_success`` and the episode's
    figures."""

    def __init__(self, venv: RlnavVectorEnv):
        self.venv = venv  # before the base class, which asks it for render_mode
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._next_seed: int | None = None

    def seed(self, seed: int | None = None):
        """Seeds the next reset (environment i from ``seed`` and i, as rlnav seeds a batch)."""
        self._next_seed = seed
        return [seed] * self.num_envs

    def reset(self):
        obs, _ = self.venv.reset(seed=self._next_seed)
        self._next_seed = None
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        dones = terminated | truncated
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if infos:
            fin = infos["final_info"]
            for i in np.flatnonzero(infos["_final_obs"]):
                info = {k: v[i] for k, v in fin.items() if not k.startswith("_")}
                info["terminal_observation"] = infos["final_obs"][i]
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                info["episode"] = {
                    "r": float(fin["episode_return"][i]),
                    "l": int(fin["length"][i]),
                    "t": float(fin["time"][i]),
                }
                out[i] = info
        return obs, rewards, dones, out

    def close(self) -> None:
        self.venv.close()

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def get_images(self):
        return [self.venv.sim.render(i) for i in range(self.num_envs)]


def policy_fn(model: Any, vec_normalize: Any = None):
    """A callable for :func:`rlnav.evaluate`: ``model``'s deterministic action for raw
    observations, normalised first by ``vec_normalize`` (the ``VecNormalize`` it trained
    under) when given."""

    def act(obs: np.ndarray) -> np.ndarray:
        if vec_normalize is not None:
            obs = vec_normalize.normalize_obs(obs)
        return model.predict(obs, deterministic=True)[0]

    return act
