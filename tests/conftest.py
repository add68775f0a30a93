"""Test-session setup shared by every test package."""

from __future__ import annotations

import ctypes.util
import os

import pytest

# Without a display MuJoCo's default GLFW backend aborts the whole process on the first render call (no
# exception to catch). `make test` exports MUJOCO_GL=egl; a bare `pytest` gets the same default here, before
# anything imports mujoco, when Mesa's EGL is installed (rendering tests skip or report otherwise).
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY") and ctypes.util.find_library("EGL"):
    os.environ["MUJOCO_GL"] = "egl"


@pytest.fixture(autouse=True, scope="session")
def _sb3_logs_in_the_session_folder(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Stable-Baselines3 gives a model learning without a logger a folder of its own under the system's temporary
    directory (``SB3-<date>``, one per ``learn``, never removed): the tests' go to the session's folder instead."""
    os.environ.setdefault("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))


def require_mujoco_warp() -> None:
    """Skip the calling test (or module) without MuJoCo Warp, except under CI (``CI=true``), where ``make test``
    installs the ``gpu`` extra and a missing package is a failure, never a skip."""
    import pytest

    try:
        import mujoco_warp  # noqa: F401
    except ImportError:
        if os.environ.get("CI") == "true":
            raise
        pytest.skip("mujoco-warp is not installed (pip install 'margin_rl[gpu]')", allow_module_level=True)
