"""rlnav for Python: the batched 2D navigation simulator as Gymnasium environments.

``rlnav.make_vec`` gives a :class:`gymnasium.vector.VectorEnv` of N differential-drive robots
with a 2D lidar, stepped in Rust with the GIL released; ``rlnav.make`` gives one
:class:`gymnasium.Env`. Scenarios, robots and tasks are the same YAML (shipped names or
files) and give the same errors as the ``rlnav`` command line. ``rlnav.evaluate`` runs a
Python policy through a benchmark suite beside the classical baseline, as ``rlnav bench``
does; ``rlnav.export`` writes a PyTorch actor as an ONNX policy with rlnav's contract, which
``rlnav ros2 node`` runs.
"""

from ._rlnav import (
    OnnxPolicy,
    RlnavError,
    VecSim,
    __version__,
    load_robot,
    load_scenario,
    load_task,
    robots,
    scenarios,
)
from . import export
from .env import RlnavEnv, make
from .evaluate import Report, evaluate
from .registration import env_id, register_envs
from .vector import RlnavVectorEnv, make_vec

register_envs()

__all__ = [
    "OnnxPolicy",
    "Report",
    "RlnavEnv",
    "RlnavError",
    "RlnavVectorEnv",
    "VecSim",
    "__version__",
    "env_id",
    "evaluate",
    "export",
    "load_robot",
    "load_scenario",
    "load_task",
    "make",
    "make_vec",
    "register_envs",
    "robots",
    "scenarios",
]
