"""Env steps per second from Python: rlnav.make_vec with random actions, next to the same
batch stepped in Rust alone (`rlnav sim-speed`'s measure) and a Gymnasium reference vector
env of similar observation size; optionally Stable-Baselines3's PPO loop on rlnav.

    python python/benchmarks/throughput.py [--envs 64] [--steps 2000] [--threads 0] [--sb3]

Build the package in release for figures worth quoting (`pip install ./python`).
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np

import rlnav


def rlnav_random(envs: int, steps: int, threads: int, scenario: str) -> float:
    venv = rlnav.make_vec(scenario=scenario, num_envs=envs, seed=0, threads=threads, copy=False)
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, envs, 2)).astype(np.float32)
    for a in actions[: steps // 10]:  # warm-up: first resets, caches
        venv.step(a)
    t = time.perf_counter()
    for a in actions:
        venv.step(a)
    return envs * steps / (time.perf_counter() - t)


def gymnasium_reference(envs: int, steps: int) -> float:
    """A MuJoCo-free reference with a comparable observation: Gymnasium's own vectorised
    CartPole (numpy, `vector_entry_point`), the fastest vector env Gymnasium ships."""
    venv = gym.make_vec("CartPole-v1", num_envs=envs, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    a = np.zeros(envs, dtype=np.int64)
    t = time.perf_counter()
    for _ in range(steps):
        venv.step(a)
    return envs * steps / (time.perf_counter() - t)


def sb3_ppo(envs: int, total: int, scenario: str) -> float:
    import torch
    from stable_baselines3 import PPO

    from rlnav.sb3 import Sb3VecEnv

    torch.set_num_threads(1)
    venv = Sb3VecEnv(rlnav.make_vec(scenario=scenario, num_envs=envs, seed=0, threads=1))
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=1024, n_epochs=5, policy_kwargs=dict(net_arch=[64, 64]), device="cpu")
    t = time.perf_counter()
    model.learn(total_timesteps=total)
    return total / (time.perf_counter() - t)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--scenario", default="random-static")
    p.add_argument("--sb3", action="store_true", help="also time SB3's PPO loop (200k steps)")
    a = p.parse_args()
    out = {
        "scenario": a.scenario,
        "envs": a.envs,
        "rlnav_random_actions_steps_per_s": rlnav_random(a.envs, a.steps, a.threads, a.scenario),
        "gymnasium_cartpole_vector_steps_per_s": gymnasium_reference(a.envs, a.steps),
    }
    if a.sb3:
        out["sb3_ppo_steps_per_s"] = sb3_ppo(32, 200_000, a.scenario)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
