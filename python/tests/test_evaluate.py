"""Evaluation of a Python policy as ``rlnav bench`` evaluates controllers, and a PyTorch actor
exported as an rlnav policy file that the Rust runtime (bench, ros2 node) drives the same."""

import json

import numpy as np
import pytest

import rlnav
from conftest import require

OBS = rlnav.VecSim("empty-room").describe()
BEARING = next(t["start"] for t in OBS["observation"] if t["name"] == "goal_bearing")


def turn_to_goal(obs):
    """Turns on the spot towards the goal, then drives: a blind controller as a batch callable."""
    g = obs[:, BEARING]
    return np.stack([np.where(np.abs(g) < 0.3, 0.5, -1.0), np.clip(2.0 * g, -1.0, 1.0)], axis=1)


def test_a_callable_runs_beside_the_baselines_on_the_same_scenes(tmp_path):
    r = rlnav.evaluate(turn_to_goal, scenario="empty-room", episodes=12, seed=3, baselines=["dwa", "greedy"], out=tmp_path)
    assert r.controllers == ["python", "dwa", "greedy"]
    # An empty room is solved by all three, and the table says so.
    for c in r.controllers:
        assert r.success_rate(c) == 1.0, r.markdown
        assert r.summary(c)["episodes"] == 12
    assert "| empty-room | python | 100% [" in r.markdown
    # Episode k is the same scene for every controller.
    starts = {c: [e["initial_distance"] for e in r.episodes(c)] for c in r.controllers}
    assert starts["python"] == starts["dwa"] == starts["greedy"]
    # The files rlnav bench writes.
    for f in ["report.md", "report.json", "report.html", "trajectories_empty-room_python.svg"]:
        assert (tmp_path / f).is_file(), f
    saved = json.loads((tmp_path / "report.json").read_text())
    assert len(saved["suites"][0]["cells"][0]["traces"]) == 12
    # Blind to obstacles, it collides where DWA does not.
    r = rlnav.evaluate(turn_to_goal, scenario="random-static", episodes=20, seed=3)
    assert r.success_rate("python") < r.success_rate("dwa")


def test_the_baselines_run_under_the_baseline_task(tmp_path):
    slow = tmp_path / "slow.yaml"
    slow.write_text("action:\n  linear: [0.05, 0.15]\n  angular: [-0.5, 0.5]\n")
    fast = rlnav.evaluate(turn_to_goal, scenario="empty-room", episodes=6, seed=3)
    capped = rlnav.evaluate(turn_to_goal, scenario="empty-room", episodes=6, seed=3, baseline_task=slow)
    # DWA keeps to the slower ranges; the Python policy keeps its own task.
    assert capped.summary("dwa")["mean_speed"] <= 0.15 + 1e-3 < fast.summary("dwa")["mean_speed"]
    assert capped.summary("python")["mean_speed"] == pytest.approx(fast.summary("python")["mean_speed"])
    assert capped.summary("dwa")["mean_task_time"] > fast.summary("dwa")["mean_task_time"]
    with pytest.raises(rlnav.RlnavError, match="no-such-task.yaml"):
        rlnav.evaluate(turn_to_goal, scenario="empty-room", episodes=1, baseline_task=tmp_path / "no-such-task.yaml")


def test_bad_policies_and_arguments_are_named():
    cases = [
        (lambda o: np.zeros((len(o), 3), np.float32), "must return shape (2, 2), got [2, 3]"),
        (lambda o: np.full((len(o), 2), np.nan), "row 0 is not finite"),
        (lambda o: 1 / 0, "ZeroDivisionError"),
    ]
    for policy, message in cases:
        with pytest.raises(rlnav.RlnavError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
            rlnav.evaluate(policy, scenario="empty-room", episodes=2)
    with pytest.raises(rlnav.RlnavError, match="one of `suite`"):
        rlnav.evaluate(turn_to_goal)
    with pytest.raises(rlnav.RlnavError, match="no-such-suite"):
        rlnav.evaluate(turn_to_goal, "no-such-suite")
    with pytest.raises(rlnav.RlnavError, match="unknown controller `nope`"):
        rlnav.evaluate(turn_to_goal, scenario="empty-room", episodes=1, baselines=["nope"])


def test_a_torch_actor_exports_to_a_policy_the_rust_runtime_drives_the_same(tmp_path):
    torch = require("torch")
    nn = torch.nn
    torch.manual_seed(0)
    n = OBS["obs_dim"]
    actor = nn.Sequential(nn.Linear(n, 32), nn.Tanh(), nn.Sequential(nn.Linear(32, 16), nn.ELU()), nn.Linear(16, 2))
    rng = np.random.default_rng(0)
    mean, var = rng.uniform(0, 2, n), rng.uniform(0.5, 2, n)
    path = tmp_path / "actor.onnx"
    contract = rlnav.export.export_torch(actor, path, robot="jetbot", obs_mean=mean, obs_var=var, clip_obs=5.0)
    assert contract["robot"] == "jetbot" and contract["action"]["scaling"] == "normalized"
    assert len(contract["observation"]) == len(OBS["observation"])

    def torch_policy(obs):
        x = np.clip((obs - mean) / np.sqrt(var + 1e-8), -5.0, 5.0)
        with torch.no_grad():
            return actor(torch.as_tensor(x, dtype=torch.float32)).numpy()

    # The file computes what torch computes.
    onnx = rlnav.OnnxPolicy(str(path))
    x = rng.uniform(0.0, 3.0, (64, n)).astype(np.float32)
    assert np.abs(onnx(x) - torch_policy(x)).max() < 1e-5
    assert onnx.contract == contract
    # And drives the same episodes as the torch actor when bench runs it as a controller
    # (observation built from scan and odometry, as on a robot).
    r = rlnav.evaluate(torch_policy, scenario="random-static", episodes=10, seed=1, baselines=[f"rl:{path}"])
    same = [
        (a["outcome"], a["length"]) == (b["outcome"], b["length"])
        for a, b in zip(r.episodes("python"), r.episodes(f"rl:{path}"))
    ]
    assert sum(same) >= 9, r.markdown
    # What the export cannot write is refused, naming the module; nothing is left behind.
    with pytest.raises(rlnav.RlnavError, match=r"module 1 \(Sigmoid\)"):
        rlnav.export.export_torch(nn.Sequential(nn.Linear(n, 4), nn.Sigmoid(), nn.Linear(4, 2)), tmp_path / "x.onnx", robot="jetbot")
    with pytest.raises(rlnav.RlnavError, match="layer 0 takes 10 values, expected 124"):
        rlnav.export.export_torch(nn.Sequential(nn.Linear(10, 2)), tmp_path / "y.onnx", robot="jetbot")
    with pytest.raises(rlnav.RlnavError, match="2 outputs"):
        rlnav.export.export_torch(nn.Linear(n, 3), tmp_path / "z.onnx", robot="jetbot")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["actor.onnx"]
