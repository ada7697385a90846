"""Rollouts spread over a Ray cluster: :class:`RayVectorEnv` is one Gymnasium vector env whose
environments live in Ray actors, each actor a Rust batch (:class:`rlnav.RlnavVectorEnv`) on
its own machine or process. Any learner that takes a Gymnasium vector env (or SB3 through
:class:`rlnav.sb3.Sb3VecEnv`) trains on it unchanged.

On several machines: ``ray start --head`` on one, ``ray start --address=HEAD_IP:6379`` on the
others, then ``ray.init(address="auto")`` before building the env (see python/README.md).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import ray
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .vector import RlnavVectorEnv


class _Batch:
    """One worker: a Rust batch stepped where the actor runs."""

    def __init__(self, scenario, robot, task, num_envs, seed, threads):
        self.venv = RlnavVectorEnv(scenario, robot, task, num_envs, seed, threads)

    def node(self) -> str:
        return f"{ray.util.get_node_ip_address()}:{os.getpid()}"

    def reset(self, seed):
        return self.venv.reset(seed=seed)[0]

    def step(self, actions):
        return self.venv.step(actions)


def _worker_seed(seed: int, k: int) -> int:
    """Worker k's batch seed: unrelated streams for unrelated workers, the same for a seed."""
    return int(np.random.SeedSequence([seed, k]).generate_state(1, np.uint64)[0] >> np.uint64(1))


class RayVectorEnv(VectorEnv):
    """``num_workers × envs_per_worker`` environments in ``num_workers`` Ray actors (each
    asking for ``cpus_per_worker`` CPUs). Layout and autoreset are
    :class:`rlnav.RlnavVectorEnv`'s: environment ``k * envs_per_worker + i`` is worker k's i-th."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        scenario: str = "random-static",
        robot: str | None = None,
        task: str | os.PathLike | None = None,
        num_workers: int = 2,
        envs_per_worker: int = 32,
        seed: int = 0,
        cpus_per_worker: float = 1,
    ):
        if not ray.is_initialized():
            raise RuntimeError("ray.init() first (ray.init() for this machine, ray.init(address='auto') for a cluster)")
        task = os.fspath(task) if task is not None else None
        remote = ray.remote(num_cpus=cpus_per_worker)(_Batch)
        threads = max(1, int(cpus_per_worker))
        self.workers = [
            remote.remote(scenario, robot, task, envs_per_worker, _worker_seed(seed, k), threads) for k in range(num_workers)
        ]
        # Built here too for the spaces (and to fail here, with the file's error, on bad input).
        probe = RlnavVectorEnv(scenario, robot, task, 1, seed, 1)
        self.description = probe.description
        self.per_worker = envs_per_worker
        self.num_envs = num_workers * envs_per_worker
        self.single_observation_space = probe.single_observation_space
        self.single_action_space = probe.single_action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def nodes(self) -> list[str]:
        """Where each worker runs (`ip:pid`)."""
        return ray.get([w.node.remote() for w in self.workers])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        seeds = [None if seed is None else _worker_seed(seed, k) for k in range(len(self.workers))]
        obs = ray.get([w.reset.remote(s) for w, s in zip(self.workers, seeds)])
        return np.concatenate(obs), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, 2)
        m = self.per_worker
        parts = ray.get([w.step.remote(actions[k * m : (k + 1) * m]) for k, w in enumerate(self.workers)])
        obs = np.concatenate([p[0] for p in parts])
        rew = np.concatenate([p[1] for p in parts])
        term = np.concatenate([p[2] for p in parts])
        trunc = np.concatenate([p[3] for p in parts])
        return obs, rew, term, trunc, _merge_infos([p[4] for p in parts], m, self.num_envs)

    def close_extras(self, **kwargs):
        for w in self.workers:
            ray.kill(w)
        self.workers = []


def _merge_infos(infos: list[dict[str, Any]], m: int, n: int) -> dict[str, Any]:
    """The workers' infos (Gymnasium's layout: arrays over each worker's envs with `_key`
    masks, nested dicts alike) as one dict over all `n` envs, worker k's rows at `k * m`."""
    out: dict[str, Any] = {}
    for k, info in enumerate(infos):
        _merge_into(out, info, k * m, m, n)
    return out


def _merge_into(acc: dict[str, Any], info: dict[str, Any], at: int, m: int, n: int) -> None:
    for key, value in info.items():
        if isinstance(value, dict):
            _merge_into(acc.setdefault(key, {}), value, at, m, n)
            continue
        if key not in acc:
            acc[key] = np.full(n, None if value.dtype == object else 0, dtype=value.dtype)
        acc[key][at : at + m] = value
