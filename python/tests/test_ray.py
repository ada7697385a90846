"""Scale-out on Ray: a local cluster of 2 workers, each a Rust batch, as one vector env that
SB3 trains on."""

import numpy as np
import pytest

import rlnav
from conftest import require


@pytest.fixture(scope="module")
def cluster():
    ray = require("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def test_two_workers_step_as_one_vector_env(cluster):
    from rlnav.ray import RayVectorEnv

    venv = RayVectorEnv("random-static", num_workers=2, envs_per_worker=16, seed=0)
    nodes = venv.nodes()
    assert len(nodes) == 2 and nodes[0] != nodes[1]  # two worker processes
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (32, 124) and venv.observation_space.contains(obs)
    # The two workers draw different scenes; the same seed draws the same ones again.
    assert not np.array_equal(obs[:16], obs[16:])
    again, _ = venv.reset(seed=0)
    assert np.array_equal(obs, again)

    rng = np.random.default_rng(0)
    lengths = np.zeros(32, dtype=np.int64)
    ended_per_worker = [0, 0]
    for _ in range(200):
        obs, rew, term, trunc, info = venv.step(rng.uniform(-1, 1, (32, 2)).astype(np.float32))
        lengths += 1
        done = term | trunc
        if done.any():
            assert np.array_equal(info["_final_obs"], done)
            for i in np.flatnonzero(done):
                # Each ended episode's figures sit at its own env's row.
                assert info["final_info"]["length"][i] == lengths[i]
                assert info["final_obs"][i].shape == (124,)
                ended_per_worker[i // 16] += 1
                lengths[i] = 0
    # 28-43 episodes per worker of 16 envs in 200 random steps (seeds 0-4, measured locally).
    assert min(ended_per_worker) > 5
    venv.close()


def test_sb3_trains_on_the_ray_workers(cluster):
    require("stable_baselines3")
    from stable_baselines3 import PPO

    from rlnav.ray import RayVectorEnv
    from rlnav.sb3 import Sb3VecEnv

    venv = Sb3VecEnv(RayVectorEnv("empty-room", num_workers=2, envs_per_worker=16, seed=1))
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=512, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=4096)
    # Episodes ran on both workers and reached SB3's episode buffer.
    assert model.num_timesteps >= 4096 and len(model.ep_info_buffer) > 0
    venv.close()
