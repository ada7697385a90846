"""Learning from Python: Stable-Baselines3's PPO on the Rust batch learns empty-room and
reaches goals on episodes it never trained on (a fresh seed)."""

import numpy as np

import rlnav
from conftest import require

# Success on 50 unseen empty-room episodes after 1 M steps, seeds 0-3 (this machine,
# 2026-12-02): 1.00, 1.00, 1.00, 0.96; the threshold keeps a margin for other CPUs.
SUCCESS = 0.8
STEPS = 1_000_000


def test_sb3_ppo_learns_empty_room(tmp_path):
    require("stable_baselines3")
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from rlnav.sb3 import Sb3VecEnv

    torch.set_num_threads(1)
    # rlnav's own runs weight progress by 10 (configs/static-mlp.yaml); so does this one.
    task = tmp_path / "task.yaml"
    task.write_text("reward:\n  progress: 10.0\n")
    seed = 0
    train = VecNormalize(Sb3VecEnv(rlnav.make_vec("empty-room", task=task, num_envs=32, seed=seed, threads=1)))
    model = PPO(
        "MlpPolicy", train, n_steps=128, batch_size=1024, n_epochs=5, policy_kwargs=dict(net_arch=[64, 64]),
        seed=seed, device="cpu", verbose=0,
    )
    model.learn(total_timesteps=STEPS)
    assert np.all(np.isfinite(train.obs_rms.mean))

    # 50 episodes of scenes no training env drew (another seed), the first episode of each env.
    train.training = False
    test = rlnav.make_vec("empty-room", task=task, num_envs=50, seed=1000, threads=1)
    obs, _ = test.reset(seed=1000)
    outcome = [None] * test.num_envs
    while any(o is None for o in outcome):
        action, _ = model.predict(train.normalize_obs(obs), deterministic=True)
        obs, _, _, _, info = test.step(action)
        if info:
            for i in np.flatnonzero(info["_final_info"]):
                if outcome[i] is None:
                    outcome[i] = info["final_info"]["outcome"][i]
    rate = outcome.count("success") / len(outcome)
    print(f"SB3 PPO, {STEPS} steps: success {rate:.2f} on 50 unseen episodes ({outcome.count('collision')} collisions)")
    assert rate >= SUCCESS, outcome
