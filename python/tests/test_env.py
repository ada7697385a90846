"""The Gymnasium environments: spaces, autoreset, seeding, errors, rendering."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rlnav


def test_single_env_passes_gymnasiums_checker():
    env = gym.make("rlnav/RandomStatic-v0", robot="jetbot", seed=0, render_mode="rgb_array").unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    # The one thing it may say: the goal distance has no upper bound (the task sets none).
    assert [str(w.message) for w in caught if "maximum value is infinity" not in str(w.message)] == []
    assert env.observation_space.high[120] == np.inf
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    # The default task: 120 lidar values clipped to [0.15, 3] m, goal distance and bearing, last command.
    assert env.observation_space.shape == (124,)
    assert env.observation_space.low[0] == pytest.approx(0.15) and env.observation_space.high[0] == pytest.approx(3.0)


def test_registered_ids_make_both_kinds():
    assert rlnav.env_id("random-static") == "rlnav/RandomStatic-v0"
    env = gym.make("rlnav/RandomStatic-v0")
    obs, _ = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    venv = gym.make_vec("rlnav/EmptyRoom-v0", num_envs=8, vectorization_mode="vector_entry_point")
    assert isinstance(venv.unwrapped, rlnav.RlnavVectorEnv) and venv.num_envs == 8
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (8, 124)


def drive(venv, steps, seed=0):
    """Random actions from a seeded generator; returns every step's outputs."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        a = rng.uniform(-1, 1, size=(venv.num_envs, 2)).astype(np.float32)
        out.append(venv.step(a))
    return out


def test_vector_env_autoresets_in_the_same_step():
    n = 64
    venv = rlnav.make_vec(scenario="random-static", robot="jetbot", num_envs=n, seed=0)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (n, 124) and obs.dtype == np.float32
    lengths = np.zeros(n, dtype=np.int64)
    returns = np.zeros(n)
    ended = 0
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, rew, term, trunc, info = venv.step(rng.uniform(-1, 1, (n, 2)).astype(np.float32))
        assert obs.shape == (n, 124) and rew.shape == (n,) and term.dtype == np.bool_
        assert not np.any(term & trunc)
        lengths += 1
        returns += rew
        done = term | trunc
        if not done.any():
            assert info == {}
            continue
        assert np.array_equal(info["_final_obs"], done) and np.array_equal(info["_final_info"], done)
        fin = info["final_info"]
        for i in np.flatnonzero(done):
            ended += 1
            # The episode's own figures agree with what the caller saw step by step.
            assert fin["length"][i] == lengths[i]
            assert fin["episode_return"][i] == pytest.approx(returns[i], rel=1e-4, abs=1e-3)
            assert fin["outcome"][i] in ("success", "collision", "timeout")
            assert fin["is_success"][i] == (fin["outcome"][i] == "success")
            assert (fin["outcome"][i] == "timeout") == trunc[i]
            assert venv.single_observation_space.contains(info["final_obs"][i])
            # The returned row is already the next episode's first observation.
            assert not np.array_equal(info["final_obs"][i], obs[i])
            lengths[i] = 0
            returns[i] = 0.0
        for i in np.flatnonzero(~done):
            assert info["final_obs"][i] is None
    # Random actions crash into the room's obstacles: 212-219 episodes end here for seeds 0-4.
    assert ended > 50


def test_same_seed_same_episodes_whatever_the_thread_count():
    a = rlnav.make_vec(scenario="random-static", num_envs=32, seed=5, threads=1)
    b = rlnav.make_vec(scenario="random-static", num_envs=32, seed=5, threads=2)
    oa, _ = a.reset(seed=5)
    ob, _ = b.reset(seed=5)
    assert np.array_equal(oa, ob)
    for (xa, ra, ta, _, _), (xb, rb, tb, _, _) in zip(drive(a, 100), drive(b, 100)):
        assert np.array_equal(xa, xb) and np.array_equal(ra, rb) and np.array_equal(ta, tb)
    # Another seed, other scenes.
    c = rlnav.make_vec(scenario="random-static", num_envs=32, seed=6)
    oc, _ = c.reset(seed=6)
    assert not np.array_equal(oa, oc)


def test_reset_with_a_seed_starts_over():
    venv = rlnav.make_vec(scenario="random-static", num_envs=4, seed=0)
    first, _ = venv.reset(seed=11)
    drive(venv, 20)
    again, _ = venv.reset(seed=11)
    assert np.array_equal(first, again)
    other, _ = venv.reset()
    assert not np.array_equal(first, other)


def test_copy_false_gives_the_buffer_itself():
    venv = rlnav.make_vec(scenario="empty-room", num_envs=2, seed=0, copy=False)
    a, _ = venv.reset(seed=0)
    b = venv.step(np.zeros((2, 2), np.float32))[0]
    assert a is b


def test_bad_files_and_inputs_are_clear_errors(tmp_path):
    bad = tmp_path / "room.yaml"
    bad.write_text("name: room\nrobot: jetbot\narena: {size: [6.0, 6.0]}\nstart: free\ngoal: free\nstart_goal_distanse: [1, 4]\n")
    with pytest.raises(rlnav.RlnavError, match=r"room\.yaml.*start_goal_distanse"):
        rlnav.make(scenario=str(bad))
    with pytest.raises(rlnav.RlnavError, match="no-such-scenario.*random-static"):
        rlnav.make_vec(scenario="no-such-scenario")
    task = tmp_path / "task.yaml"
    task.write_text("control_period: 0.03\n")
    with pytest.raises(rlnav.RlnavError, match=r"task\.yaml.*control_period"):
        rlnav.make_vec(scenario="empty-room", task=task)
    with pytest.raises(rlnav.RlnavError, match=r"missing\.yaml: cannot read"):
        rlnav.load_robot(str(tmp_path / "missing.yaml"))
    venv = rlnav.make_vec(scenario="empty-room", num_envs=3, seed=0)
    venv.reset(seed=0)
    with pytest.raises(rlnav.RlnavError, match=r"actions: expected shape \(3, 2\)"):
        venv.sim.step(np.zeros((2, 2), np.float32), *venv_buffers(venv))
    nan = np.zeros((3, 2), np.float32)
    nan[1, 0] = np.nan
    with pytest.raises(rlnav.RlnavError, match=r"actions\[1\]: expected finite"):
        venv.step(nan)


def venv_buffers(venv):
    return venv._obs, venv._rewards, venv._terminated, venv._truncated, venv._final_obs


def test_loaders_give_the_specs():
    assert "random-static" in rlnav.scenarios() and "turtlebot3-burger" in rlnav.robots()
    assert rlnav.load_robot("jetbot")["name"] == "jetbot"
    assert rlnav.load_scenario("empty-room")["start_goal_distance"] == [1.0, 4.0]
    assert rlnav.load_task()["max_steps"] == 1200


def test_other_robots_and_their_lidars():
    venv = rlnav.make_vec(scenario="random-static", robot="turtlebot3-burger", num_envs=4, seed=0)
    assert venv.description["robot"]["name"] == "turtlebot3-burger"
    obs, _ = venv.reset(seed=0)
    assert venv.observation_space.contains(obs)


def test_render_draws_the_scene():
    env = rlnav.make(scenario="random-static", seed=0, render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and max(img.shape[:2]) == 400
    # White floor, grey obstacles and the blue robot are all there.
    colours = {tuple(c) for c in img.reshape(-1, 3)[::7]}
    assert (255, 255, 255) in colours and len(colours) > 10
    frames = rlnav.make_vec(scenario="empty-room", num_envs=2, render_mode="rgb_array").render()
    assert len(frames) == 2 and frames[0].shape[2] == 3
