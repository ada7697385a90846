"""A PyTorch actor as an rlnav policy file: ONNX with rlnav's observation/action contract
inside, which ``rlnav bench``, ``rlnav eval`` and ``rlnav ros2 node`` run as they run the
policies ``rlnav train`` writes.

Feed-forward actors of ``Linear`` layers with ``Tanh``, ``ReLU`` or ``ELU`` between them are
exported (the last ``Linear`` gives the normalised action mean); the observation
normalisation goes into the graph in front of them."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from . import _rlnav


def _flatten(module: Any) -> list[Any]:
    import torch.nn as nn

    if isinstance(module, nn.Sequential):
        return [m for child in module for m in _flatten(child)]
    if isinstance(module, (list, tuple)):
        return [m for child in module for m in _flatten(child)]
    return [module]


def torch_layers(actor: Any) -> list[tuple[np.ndarray, np.ndarray, str | None]]:
    """``actor`` (an ``nn.Sequential``, or a list of modules, nested as you like) as
    ``(weight[in, out], bias[out], activation)`` layers. Refuses what the export does not
    write, naming the module."""
    import torch.nn as nn

    layers: list[list[Any]] = []
    for i, m in enumerate(_flatten(actor)):
        if isinstance(m, (nn.Identity, nn.Flatten)):
            continue
        if isinstance(m, nn.Linear):
            w = m.weight.detach().cpu().numpy().astype(np.float32)
            b = (
                m.bias.detach().cpu().numpy().astype(np.float32)
                if m.bias is not None
                else np.zeros(m.out_features, np.float32)
            )
            layers.append([np.ascontiguousarray(w.T), b, None])
            continue
        act = {nn.Tanh: "tanh", nn.ReLU: "relu"}.get(type(m))
        if isinstance(m, nn.ELU):
            if m.alpha != 1.0:
                raise _rlnav.RlnavError(f"module {i} ({m}): only ELU with alpha 1 is exported")
            act = "elu"
        if act is None:
            raise _rlnav.RlnavError(
                f"module {i} ({type(m).__name__}): expected Linear, Tanh, ReLU, ELU, Identity or Flatten"
            )
        if not layers or layers[-1][2] is not None:
            raise _rlnav.RlnavError(f"module {i} ({type(m).__name__}): an activation must follow a Linear")
        layers[-1][2] = act
    return [tuple(layer) for layer in layers]


def export_torch(
    actor: Any,
    path: str | os.PathLike,
    *,
    robot: str | os.PathLike,
    task: str | os.PathLike | None = None,
    obs_mean: np.ndarray | None = None,
    obs_var: np.ndarray | None = None,
    epsilon: float = 1e-8,
    clip_obs: float = math.inf,
    name: str = "python",
) -> dict[str, Any]:
    """Writes ``actor`` (raw task observation → normalised action mean, after
    ``(obs - obs_mean) / sqrt(obs_var + epsilon)`` clipped to ``±clip_obs`` when a mean and
    variance are given) to ``path`` as an ONNX policy for ``robot`` under ``task`` (a task
    file; default the built-in task: the observation layout the actor was trained on). The
    file is loaded back and checked against the robot's lidar before it replaces ``path``.
    Returns the contract written into it."""
    layers = torch_layers(actor)
    if not layers:
        raise _rlnav.RlnavError("actor: no Linear layers")
    n = layers[0][0].shape[0]
    if obs_mean is None and obs_var is None:
        scale, shift = np.ones(n, np.float32), np.zeros(n, np.float32)
    elif obs_mean is not None and obs_var is not None:
        mean = np.asarray(obs_mean, np.float64).reshape(-1)
        var = np.asarray(obs_var, np.float64).reshape(-1)
        scale64 = 1.0 / np.sqrt(var + epsilon)
        scale, shift = scale64.astype(np.float32), (-mean * scale64).astype(np.float32)
    else:
        raise _rlnav.RlnavError("give both obs_mean and obs_var, or neither")
    return _rlnav.export_mlp(
        os.fspath(path),
        layers,
        scale.tolist(),
        shift.tolist(),
        float(clip_obs),
        robot=os.fspath(robot),
        task=None if task is None else os.fspath(task),
        name=name,
    )


def export_sb3(
    model: Any,
    path: str | os.PathLike,
    *,
    robot: str | os.PathLike,
    task: str | os.PathLike | None = None,
    vec_normalize: Any = None,
    name: str = "sb3",
) -> dict[str, Any]:
    """Writes a Stable-Baselines3 model with an MLP actor-critic (PPO, A2C) to ``path`` as
    :func:`export_torch` does: its actor (``mlp_extractor.policy_net`` then ``action_net``)
    and, with ``vec_normalize`` (the ``VecNormalize`` it trained under), the observation
    normalisation."""
    policy = getattr(model, "policy", model)
    for attr in ("mlp_extractor", "action_net"):
        if not hasattr(policy, attr):
            raise _rlnav.RlnavError(f"model: expected an SB3 actor-critic policy with `{attr}` (PPO or A2C, MlpPolicy)")
    if getattr(policy, "squash_output", False):
        raise _rlnav.RlnavError("model: a squashed (tanh) action output is not exported")
    from stable_baselines3.common.torch_layers import FlattenExtractor

    extractor = getattr(policy, "pi_features_extractor", None) or policy.features_extractor
    if not isinstance(extractor, FlattenExtractor):
        raise _rlnav.RlnavError(f"model: expected the flatten features extractor, got {type(extractor).__name__}")
    kw: dict[str, Any] = {}
    if vec_normalize is not None and getattr(vec_normalize, "norm_obs", False):
        rms = vec_normalize.obs_rms
        kw = dict(obs_mean=rms.mean, obs_var=rms.var, epsilon=vec_normalize.epsilon, clip_obs=vec_normalize.clip_obs)
    actor = [policy.mlp_extractor.policy_net, policy.action_net]
    return export_torch(actor, path, robot=robot, task=task, name=name, **kw)
