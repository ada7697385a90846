"""Learning from Python: Stable-Baselines3's PPO on the Rust batch learns empty-room and
reaches goals on episodes it never trained on (a fresh seed), evaluated by ``rlnav.evaluate``
beside DWA, and its export drives as it does."""

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

    from rlnav.sb3 import Sb3VecEnv, policy_fn

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

    # 50 episodes of scenes no training env drew (another seed), DWA beside it; then the
    # policy exported with its normalisation, driven by the Rust runtime that bench and the
    # ROS 2 node use.
    train.training = False
    onnx = tmp_path / "sb3.onnx"
    rlnav.export.export_sb3(model, onnx, robot="jetbot", task=task, vec_normalize=train)
    policy = policy_fn(model, train)
    report = rlnav.evaluate(
        policy, scenario="empty-room", task=task, episodes=50, seed=1000, baselines=["dwa", f"rl:{onnx}"]
    )
    print(report.markdown)
    rate = report.success_rate("python")
    print(f"SB3 PPO, {STEPS} steps: success {rate:.2f} on 50 unseen episodes, DWA {report.success_rate('dwa'):.2f}")
    assert rate >= SUCCESS, report.markdown
    # The exported file acts as the SB3 policy does (before SB3 clips to the action space).
    obs = np.random.default_rng(0).uniform(0.2, 3.0, (64, train.observation_space.shape[0])).astype(np.float32)
    with torch.no_grad():
        x = torch.as_tensor(train.normalize_obs(obs), dtype=torch.float32)
        mu = model.policy.action_net(model.policy.mlp_extractor.forward_actor(x)).numpy()
    assert np.abs(rlnav.OnnxPolicy(str(onnx))(obs) - mu).max() < 1e-4
    onnx_rate = report.success_rate(f"rl:{onnx}")
    assert abs(onnx_rate - rate) <= 0.04, report.markdown
