"""The MuJoCo model of an environment: the robot's MJCF on flat ground or on a generated heightfield."""

from __future__ import annotations

from pathlib import Path

import mujoco

from margin_rl.envs.terrain import Terrain, TerrainConfig
from margin_rl.robot import Robot
from margin_rl.robot.mjcf_names import FLOOR_GEOM


def build_model(robot: Robot, terrain: Terrain, terrain_config: TerrainConfig) -> mujoco.MjModel:
    """The robot on its terrain: the flat scene file, or the robot plus a heightfield of ``terrain``.

    The heightfield spans the terrain's grid centred on the world origin; its top is
    ``terrain_config.max_height`` [m] and the floor geom keeps the name :data:`~margin_rl.robot.mjcf_names.FLOOR_GEOM`
    (``floor``, friction 1.0) in both cases (the flat scene files name it so), so the environment finds it by name.
    """
    if terrain.is_flat:
        return mujoco.MjModel.from_xml_path(str(robot.scene_path))
    h = terrain.heights
    rows, columns = h.shape
    half_x, half_y = (columns - 1) * terrain.resolution / 2, (rows - 1) * terrain.resolution / 2
    z_top = terrain_config.max_height
    xml = f"""
<mujoco model="{robot.name}_rough">
  <include file="{Path(robot.xml_path).as_posix()}"/>
  <visual><global offwidth="1280" offheight="720"/></visual>
  <asset>
    <hfield name="terrain" nrow="{rows}" ncol="{columns}" size="{half_x} {half_y} {z_top} 0.1"/>
    <texture type="2d" name="grid" builtin="checker" rgb1="0.35 0.4 0.45" rgb2="0.25 0.3 0.35" width="300"
             height="300"/>
    <material name="grid" texture="grid" texrepeat="24 24"/>
  </asset>
  <worldbody>
    <light pos="0 0 5" dir="0 0 -1" directional="true"/>
    <geom name="{FLOOR_GEOM}" type="hfield" hfield="terrain" material="grid" contype="1" conaffinity="1" condim="3"
          friction="1.0 0.005 0.0001" priority="1"/>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    # MuJoCo hfield data: row-major, rows along y, columns along x, values in [0, 1] of z_top.
    model.hfield_data[:] = (h / z_top).ravel()
    return model
