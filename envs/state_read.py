"""Reading the robot's world-frame state (:class:`~margin_rl.envs.step_data.SimulationState`) from the physics' live
arrays, in few operations: the float sources (qpos, qvel, sensordata, the foot sites, the knees) gathered into one
block and converted to float64 once, every field a view of that block, the three contact sensors compared in one go.
On a device every operation is a kernel launched from Python, so the read costs what it dispatches, not what it
computes. Robot names (bodies, sites, sensors, the qpos/qvel layout) come from :mod:`margin_rl.robot.mjcf_names`."""

from __future__ import annotations

from typing import Any

from margin_rl.arrays import finite_mask, like, namespace, rotate
from margin_rl.envs.physics import PhysicsBackend
from margin_rl.envs.step_data import SimulationState
from margin_rl.robot import Robot, quat_wxyz_to_matrix
from margin_rl.robot import mjcf_names as names


def _shifted(columns: slice, offset: int, width: int) -> slice:
    """``columns`` of a row of ``width`` entries, as columns of a block where that row starts at ``offset``."""
    start, stop, _ = columns.indices(width)
    return slice(offset + start, offset + stop)


class StateReader:
    """The state of some environments, read from ``physics`` (numpy beside ``mujoco.batch``, torch tensors on the
    device beside Warp; float64 either way)."""

    def __init__(self, physics: PhysicsBackend, robot: Robot) -> None:
        self.physics = physics
        nq, nv = int(physics.qpos.shape[1]), int(physics.qvel.shape[1])
        nsensor = int(physics.sensordata.shape[1])
        legs = robot.leg_names

        def index(values: list[int]) -> Any:
            return like(values, physics.qpos, namespace(physics.qpos).int64)

        # the foot sites (spheres' centres) in the robot's leg order, also read by the critic's terrain heights
        self.feet_sites = index([physics.site_id(f) for f in robot.foot_names])
        # The shank body's origin is the knee (KFE) joint, the lower end of the thigh whose contact ends an episode.
        self._knees = index([physics.body_id(names.shank_body(leg)) for leg in legs])
        # Columns of the block: qpos | qvel | sensordata | feet (4 x 3) | knees (4 x 3).
        sensors = nq + nv
        self._base_pos = _shifted(names.BASE_POSITION_QPOS, 0, nq)
        self._quat = _shifted(names.BASE_QUATERNION_QPOS, 0, nq)
        self._joint_pos = _shifted(names.JOINT_QPOS, 0, nq)
        self._lin_vel = _shifted(names.BASE_LINEAR_VELOCITY_QVEL, nq, nv)
        self._ang_vel = _shifted(names.BASE_ANGULAR_VELOCITY_QVEL, nq, nv)
        self._joint_vel = _shifted(names.JOINT_QVEL, nq, nv)
        self._com = _shifted(physics.sensor_slice(names.COM_SENSOR), sensors, nsensor)
        self._com_vel = _shifted(physics.sensor_slice(names.COM_VELOCITY_SENSOR), sensors, nsensor)
        self._feet_columns = slice(sensors + nsensor, sensors + nsensor + 12)
        self._knee_columns = slice(sensors + nsensor + 12, sensors + nsensor + 24)
        # First entry ("found") of each contact sensor: the feet, the thighs, the base, compared in one gather.
        found = [physics.sensor_adr(names.foot_contact_sensor(leg)) for leg in legs]
        found += [physics.sensor_adr(names.thigh_contact_sensor(leg)) for leg in legs]
        found.append(physics.sensor_adr(names.BASE_CONTACT_SENSOR))
        self._contact_columns = index([sensors + adr for adr in found])

    def read(self, ids: Any = slice(None), finite: bool = False) -> SimulationState:
        """World-frame state of environments ``ids`` (an index array, or ``slice(None)`` for all).

        ``finite``: every non-finite float of the state replaced by 0 (a diverged step's bookkeeping), the derived
        ones (orientation, world-frame angular velocity) computed from the raw values first, as for any state.
        """
        physics = self.physics
        xp = namespace(physics.qpos)
        every = isinstance(ids, slice) and ids == slice(None)

        def rows(array: Any) -> Any:
            return array if every else array[ids]

        feet, knees = rows(physics.site_xpos)[:, self.feet_sites], rows(physics.xpos)[:, self._knees]
        n = int(feet.shape[0])
        sources = (
            rows(physics.qpos),
            rows(physics.qvel),
            rows(physics.sensordata),
            xp.reshape(feet, (n, 12)),
            xp.reshape(knees, (n, 12)),
        )
        block = xp.astype(xp.concat(sources, axis=1), xp.float64, copy=False)
        R = quat_wxyz_to_matrix(block[:, self._quat])
        ang_vel_body = block[:, self._ang_vel]
        ang_vel_world = rotate(R, ang_vel_body)
        if finite:
            block, R, ang_vel_world = (xp.where(finite_mask(a), a, 0.0) for a in (block, R, ang_vel_world))
            ang_vel_body = block[:, self._ang_vel]
        touching = block[:, self._contact_columns] > 0
        return SimulationState(
            base_pos=block[:, self._base_pos],
            base_rot=R,
            lin_vel_world=block[:, self._lin_vel],
            ang_vel_body=ang_vel_body,
            ang_vel_world=ang_vel_world,
            joint_pos=block[:, self._joint_pos],
            joint_vel=block[:, self._joint_vel],
            com=block[:, self._com],
            com_vel=block[:, self._com_vel],
            feet=xp.reshape(block[:, self._feet_columns], (n, 4, 3)),
            contacts=touching[:, :4],
            base_contact=touching[:, 8],
            thigh_contacts=touching[:, 4:8],
            knees=xp.reshape(block[:, self._knee_columns], (n, 4, 3)),
        )
