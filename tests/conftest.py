"""Test-session setup shared by every test package."""

from __future__ import annotations

import ctypes.util
import os

# Without a display MuJoCo's default GLFW backend aborts the whole process on the first render call (no
# exception to catch). `make test` exports MUJOCO_GL=egl; a bare `pytest` gets the same default here, before
# anything imports mujoco, when Mesa's EGL is installed (rendering tests skip or report otherwise).
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY") and ctypes.util.find_library("EGL"):
    os.environ["MUJOCO_GL"] = "egl"
