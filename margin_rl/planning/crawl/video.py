"""MP4 of simulated crawls, replayed from their recorded MuJoCo states (``qpos`` per control step).

Needs ``imageio`` with ``imageio-ffmpeg`` (``pip install 'margin_rl[video]'``) and a MuJoCo rendering
backend (``MUJOCO_GL=egl`` headless); raises :class:`~margin_rl.planning.video.VideoUnavailableError`
otherwise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from margin_rl.planning.video import VideoUnavailableError
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
    try:
        import imageio.v2 as imageio
        import imageio_ffmpeg  # noqa: F401  (the MP4 backend)
    except ImportError as exc:
        raise VideoUnavailableError(
            "writing MP4 needs imageio and imageio-ffmpeg: pip install 'margin_rl[video]' (or imageio imageio-ffmpeg)"
        ) from exc
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(robot.scene_path))
    data = mujoco.MjData(model)
    try:
        renderer = mujoco.Renderer(model, height=size[1], width=size[0])
    except Exception as exc:  # GL back ends fail with several exception types
        raise VideoUnavailableError(f"MuJoCo cannot render here ({exc}); set MUJOCO_GL=egl or osmesa") from exc
    camera = mujoco.MjvCamera()
    camera.distance, camera.elevation, camera.azimuth = 2.4, -20.0, 135.0
    stride = max(1, round(1.0 / (fps * timestep)))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with imageio.get_writer(str(path), fps=fps, codec="libx264", quality=6, macro_block_size=8) as writer:
        for qpos in clips.values():
            for k in range(0, len(qpos), stride):
                data.qpos[:] = qpos[k]
                mujoco.mj_kinematics(model, data)
                camera.lookat[:] = data.qpos[0:3]
                renderer.update_scene(data, camera)
                writer.append_data(renderer.render())
    renderer.close()
    return path
