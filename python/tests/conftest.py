import os

import pytest


def require(module: str):
    """Imports an optional peer; in CI (CI set) its absence is a failure, elsewhere a skip."""
    try:
        return __import__(module)
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail(f"CI must install {module} for the Python API tests (.ci/run does)")
        pytest.skip(f"{module} not installed")
