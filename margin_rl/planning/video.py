"""MP4 of a planned course played back kinematically on the MJCF robot (base pose + IK joint angles).

Each frame: the base orientation R from the plan's roll-pitch-yaw, the joint angles from the analytic
IK of the four planned foot positions relative to the CoM (with the robot's CoM fixed point, so the
whole-body CoM sits exactly on the planned one), and the base origin c - R c_B(q). The terrain is a
MuJoCo height field built from the scenario's map. No dynamics are simulated.

Needs ``imageio`` with ``imageio-ffmpeg`` (``pip install 'margin_rl[video]'``) and a MuJoCo rendering
backend (``MUJOCO_GL=egl`` headless).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from margin_rl.planning.checks import rotation_kinematics
from margin_rl.planning.receding import CourseResult
from margin_rl.robot import Robot


class VideoUnavailableError(RuntimeError):
    """The MP4 cannot be written on this machine (missing package or rendering backend)."""


def scene_model(robot: Robot, result: CourseResult):  # -> mujoco.MjModel
    """The robot MJCF plus a visual-only height field of the scenario's map (built with MjSpec).

    MuJoCo stores a height field as values in [0, 1] of its elevation above the geom's position, so the
    map is shifted by its lowest point and scaled by its height range.
    """
    import mujoco

    hm = result.scenario.height_map
    ny, nx = hm.shape
    x_min, x_max, y_min, y_max = hm.extent
    low, high = float(hm.heights.min()), float(hm.heights.max())
    elevation = max(high - low, 1e-3)
    spec = mujoco.MjSpec.from_file(str(Path(robot.xml_path)))
    spec.visual.global_.offwidth, spec.visual.global_.offheight = 960, 540
    spec.add_hfield(
        name="terrain", nrow=ny, ncol=nx, size=[(x_max - x_min) / 2, (y_max - y_min) / 2, elevation, 0.05],
        userdata=((hm.heights - low) / elevation).ravel().tolist(),
    )  # fmt: skip
    spec.add_texture(
        name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.55, 0.6, 0.65], rgb2=[0.45, 0.5, 0.55], width=300, height=300,
    )  # fmt: skip
    material = spec.add_material(name="grid", texrepeat=[20, 8])
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "grid"
    spec.worldbody.add_light(pos=[0, 0, 6], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    spec.worldbody.add_geom(
        name="terrain", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="terrain", material="grid",
        pos=[(x_min + x_max) / 2, (y_min + y_max) / 2, low], contype=0, conaffinity=0,
    )  # fmt: skip
    return spec.compile()


def joint_configuration(robot: Robot, result: CourseResult, t: float) -> tuple[np.ndarray, bool]:
    """MuJoCo qpos (19,) of the plan at time t and whether all four feet were reachable."""
    plan = result.plan_at(t)
    c, rpy, _, _, _, _ = plan.base_at(t)
    R = rotation_kinematics(rpy, np.zeros(3), np.zeros(3))[0]
    feet = plan.foot_centres(result.scenario.height_map, robot.foot_radius, t)
    solution, com = robot.inverse_kinematics_com_relative((feet - c) @ R)
    q = np.where(np.isfinite(solution.joint_pos), solution.joint_pos, robot.standing_joint_pos)
    base = c - R @ np.asarray(com)
    w = np.sqrt(max(1.0 + np.trace(R), 1e-12)) / 2.0
    quat = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])
    return np.concatenate([base, quat, q]), bool(solution.reachable.all())


def render_mp4(
    model,  # mujoco.MjModel
    frames: Iterable[np.ndarray],
    path: str | Path,
    fps: int = 25,
    size: tuple[int, int] = (640, 360),
    camera_distance: float = 2.6,
    camera_azimuth: float = 120.0,
) -> Path:
    """Render ``frames`` (MuJoCo qpos vectors, one per video frame) of ``model`` to ``path`` (MP4), the camera
    following the base.

    Raises:
        VideoUnavailableError: imageio/imageio-ffmpeg missing, or MuJoCo cannot render here.
    """
    try:
        import imageio.v2 as imageio
        import imageio_ffmpeg  # noqa: F401  (the MP4 backend)
    except ImportError as exc:
        raise VideoUnavailableError(
            "writing MP4 needs imageio and imageio-ffmpeg: pip install 'margin_rl[video]' (or imageio imageio-ffmpeg)"
        ) from exc
    import mujoco

    data = mujoco.MjData(model)
    try:
        renderer = mujoco.Renderer(model, height=size[1], width=size[0])
    except Exception as exc:  # GL backend errors come as several types
        raise VideoUnavailableError(f"MuJoCo cannot render here ({exc}); set MUJOCO_GL=egl or osmesa") from exc
    camera = mujoco.MjvCamera()
    camera.distance, camera.elevation, camera.azimuth = camera_distance, -20.0, camera_azimuth
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with imageio.get_writer(str(path), fps=fps, codec="libx264", quality=6, macro_block_size=8) as writer:
        for qpos in frames:
            data.qpos[:] = qpos
            mujoco.mj_kinematics(model, data)
            camera.lookat[:] = data.qpos[0:3]
            renderer.update_scene(data, camera)
            writer.append_data(renderer.render())
    renderer.close()
    return path


def write_mp4(
    robot: Robot, result: CourseResult, path: str | Path, fps: int = 25, size: tuple[int, int] = (640, 360)
) -> Path:
    """Render the course to ``path`` (MP4).

    Raises:
        VideoUnavailableError: imageio/imageio-ffmpeg missing, or MuJoCo cannot render here.
    """
    times = np.arange(0.0, result.duration, 1.0 / fps)
    frames = (joint_configuration(robot, result, float(t))[0] for t in times)
    return render_mp4(scene_model(robot, result), frames, path, fps, size)
