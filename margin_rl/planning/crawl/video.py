"""MP4 of simulated crawls, replayed from their recorded MuJoCo states (``qpos`` per control step).

Needs ``imageio`` with ``imageio-ffmpeg`` (``pip install 'margin_rl[video]'``) and a MuJoCo rendering
backend (``MUJOCO_GL=egl`` headless); raises :class:`~margin_rl.planning.video.VideoUnavailableError`
otherwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from margin_rl.planning.video import render_mp4
from margin_rl.robot import Robot


def write_crawl_mp4(
    robot: Robot,
    clips: dict[str, np.ndarray],
    path: str | Path,
    timestep: float,
    fps: int = 25,
    size: tuple[int, int] = (640, 360),
) -> Path:
    """Render ``clips`` (title -> (T, 19) qpos recorded every ``timestep`` [s]) one after another into ``path``."""
    import mujoco

    stride = max(1, round(1.0 / (fps * timestep)))
    frames = (qpos[k] for qpos in clips.values() for k in range(0, len(qpos), stride))
    model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
    return render_mp4(model, frames, path, fps, size, camera_distance=2.4, camera_azimuth=135.0)
