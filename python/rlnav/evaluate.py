"""Evaluating a policy written in Python the way ``rlnav bench`` evaluates controllers: the
same seeded scenes, the classical baseline beside it, the same tables and files."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from . import _rlnav


class Report:
    """What :func:`evaluate` measured.

    ``markdown`` is ``rlnav bench``'s table (per scenario and controller, then pooled over the
    suite, rates with their 95% Wilson interval); ``data`` the figures as a dict: ``suites``
    (cells of scenario x controller with every episode) and ``pooled`` (each controller's
    summary over the suite)."""

    def __init__(self, markdown: str, data: dict[str, Any]):
        self.markdown = markdown
        self.data = data

    def __str__(self) -> str:
        return self.markdown

    @property
    def controllers(self) -> list[str]:
        """The controllers, the evaluated policy first."""
        return list(dict.fromkeys(c["controller"] for c in self.data["suites"][0]["cells"]))

    def summary(self, controller: str) -> dict[str, Any]:
        """``controller``'s figures over the whole suite (``success_rate``,
        ``success_ci95``, ``collision_rate``, ``spl``, ``mean_task_time``...)."""
        try:
            return self.data["pooled"][controller]
        except KeyError:
            raise KeyError(f"no controller {controller!r}; the report has {self.controllers}") from None

    def success_rate(self, controller: str) -> float:
        """``controller``'s success rate over the whole suite."""
        return float(self.summary(controller)["success_rate"])

    def episodes(self, controller: str, scenario: str | None = None) -> list[dict[str, Any]]:
        """Every episode of ``controller`` (on ``scenario``, or all), in seed order."""
        return [
            e
            for c in self.data["suites"][0]["cells"]
            if c["controller"] == controller and (scenario is None or c["scenario"] == scenario)
            for e in c["episodes"]
        ]


def as_policy(policy: Any) -> Callable[[np.ndarray], np.ndarray]:
    """A callable from observations ``float32[n, obs_dim]`` to actions ``float32[n, 2]``:
    for an object with ``predict`` (a Stable-Baselines3 model or policy) its deterministic
    action, else ``policy`` itself."""
    if hasattr(policy, "predict"):
        model = policy
        return lambda obs: model.predict(obs, deterministic=True)[0]
    if not callable(policy):
        raise TypeError(f"policy: expected a callable or a model with predict(), got {type(policy).__name__}")
    return policy


def evaluate(
    policy: Any,
    suite: str | os.PathLike | None = None,
    *,
    scenario: str | os.PathLike | None = None,
    robot: str | os.PathLike | None = None,
    task: str | os.PathLike | None = None,
    episodes: int | None = None,
    seed: int = 7,
    baselines: Sequence[str] = ("dwa",),
    name: str = "python",
    threads: int = 0,
    out: str | os.PathLike | None = None,
    baseline_task: str | os.PathLike | None = None,
) -> Report:
    """Runs ``policy`` through a benchmark suite (``suite``: a shipped name such as
    ``heldout-static`` or a YAML file) or one scenario (``scenario``), then each of
    ``baselines`` (``dwa``, ``greedy``, ``rl:POLICY.onnx``: what ``rlnav bench --controller``
    takes) on the same seeded scenes: episode k of a scenario is the same scene for every
    controller, and the same as ``rlnav bench --seed`` gives.

    ``policy`` maps observations ``float32[n, obs_dim]`` (the layout of ``task``: a task
    file, default the built-in one) to normalised actions ``[n, 2]`` in [-1, 1]; every
    episode of the suite runs in lockstep, one call per control step, row i always the same
    episode (rows of ended episodes are given too, their actions ignored). A Stable-Baselines3
    model is called through ``predict(obs, deterministic=True)``; observation normalisation
    (``VecNormalize``) is the callable's to apply: :func:`rlnav.sb3.policy_fn` does both.

    ``baseline_task`` is the task file the baselines run under, and the rest of the policy's
    (time limit, collision range), as ``rlnav bench --task`` sets them (default the built-in
    task): give it ``task``'s action ranges to compare like with like.
    ``episodes`` per scenario (default: the suite's; 20 for one scenario); ``robot`` replaces
    the scenarios' robot; with ``out`` the files ``rlnav bench --out`` writes (report.md,
    report.json, report.html, figures). Errors in the policy's output (shape, non-finite
    values) raise :class:`rlnav.RlnavError` naming the row."""
    if (suite is None) == (scenario is None):
        raise _rlnav.RlnavError("give one of `suite` (a suite name or file) and `scenario`")
    act = as_policy(policy)

    def call(obs: np.ndarray) -> np.ndarray:
        a = act(obs)
        if hasattr(a, "detach"):  # a torch tensor
            a = a.detach().cpu().numpy()
        return np.ascontiguousarray(np.asarray(a, dtype=np.float32).reshape(len(obs), -1))

    markdown, data = _rlnav.evaluate(
        call,
        suite=None if suite is None else os.fspath(suite),
        scenario=None if scenario is None else os.fspath(scenario),
        robot=None if robot is None else os.fspath(robot),
        task=None if task is None else os.fspath(task),
        episodes=episodes,
        seed=seed,
        threads=threads,
        baselines=list(baselines),
        name=name,
        out=None if out is None else os.fspath(out),
        baseline_task=None if baseline_task is None else os.fspath(baseline_task),
    )
    return Report(markdown, json.loads(data))
