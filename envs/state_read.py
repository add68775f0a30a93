"""Reading the robot's world-frame state (:class:`~margin_rl.envs.step_data.SimulationState`) from the physics' live
arrays, in few operations: the float sources (qpos, qvel, sensordata, the foot sites, the knees) gathered into one
block and converted to float64 once, every field a view of that block, the three contact sensors compared in one go.
On a device every operation is a kernel launched from Python, so the read costs what it dispatches, not what it
computes. Robot names (bodies, sites, sensors, the qpos/qvel layout) come from :mod:`margin_rl.robot.mjcf_names`."""

from __future__ import annotations

from typing import Any

from margin_rl.arrays import ALL_ROWS, finite_or_zero, like, namespace, rotate, rows_of, split_columns
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
        feet = sensors + nsensor
        columns = {  # each field's columns in the block
            "base_pos": _shifted(names.BASE_POSITION_QPOS, 0, nq),
            "quat": _shifted(names.BASE_QUATERNION_QPOS, 0, nq),
            "joint_pos": _shifted(names.JOINT_QPOS, 0, nq),
            "lin_vel_world": _shifted(names.BASE_LINEAR_VELOCITY_QVEL, nq, nv),
            "ang_vel_body": _shifted(names.BASE_ANGULAR_VELOCITY_QVEL, nq, nv),
            "joint_vel": _shifted(names.JOINT_QVEL, nq, nv),
            "com": _shifted(physics.sensor_slice(names.COM_SENSOR), sensors, nsensor),
            "com_vel": _shifted(physics.sensor_slice(names.COM_VELOCITY_SENSOR), sensors, nsensor),
            "feet": slice(feet, feet + 12),
            "knees": slice(feet + 12, feet + 24),
        }
        self._quat, self._ang_vel = columns["quat"], columns["ang_vel_body"]  # read raw in a finite read
        self._fields, self._widths = _field_split(columns, feet + 24)
        # First entry ("found") of each contact sensor: the feet, the thighs, the base, compared in one gather.
        found = [physics.sensor_adr(names.foot_contact_sensor(leg)) for leg in legs]
        found += [physics.sensor_adr(names.thigh_contact_sensor(leg)) for leg in legs]
        found.append(physics.sensor_adr(names.BASE_CONTACT_SENSOR))
        self._contact_columns = index([sensors + adr for adr in found])

    def read(self, ids: Any = ALL_ROWS, finite: bool = False) -> SimulationState:
        """World-frame state of environments ``ids`` (an index array, or ``ALL_ROWS``).

        ``finite``: every non-finite float of the state replaced by 0 (a diverged step's bookkeeping), the derived
        ones (orientation, world-frame angular velocity) computed from the raw values first, as for any state.
        """
        physics = self.physics
        xp = namespace(physics.qpos)
        feet, knees = rows_of(physics.site_xpos, ids)[:, self.feet_sites], rows_of(physics.xpos, ids)[:, self._knees]
        n = int(feet.shape[0])
        sources = (
            rows_of(physics.qpos, ids),
            rows_of(physics.qvel, ids),
            rows_of(physics.sensordata, ids),
            xp.reshape(feet, (n, 12)),
            xp.reshape(knees, (n, 12)),
        )
        block = xp.astype(xp.concat(sources, axis=1), xp.float64, copy=False)
        values = finite_or_zero(block) if finite else block
        field = dict(zip(self._fields, split_columns(values, self._widths), strict=True))
        # the derived fields from the raw values, then made finite like the others
        R = quat_wxyz_to_matrix(block[:, self._quat] if finite else field["quat"])
        ang_vel_world = rotate(R, block[:, self._ang_vel] if finite else field["ang_vel_body"])
        if finite:
            R, ang_vel_world = finite_or_zero(R), finite_or_zero(ang_vel_world)
        feet_touching, thighs_touching, base_touching = split_columns(values[:, self._contact_columns] > 0, (4, 4, 1))
        return SimulationState(
            base_pos=field["base_pos"],
            base_rot=R,
            lin_vel_world=field["lin_vel_world"],
            ang_vel_body=field["ang_vel_body"],
            ang_vel_world=ang_vel_world,
            joint_pos=field["joint_pos"],
            joint_vel=field["joint_vel"],
            com=field["com"],
            com_vel=field["com_vel"],
            feet=xp.reshape(field["feet"], (n, 4, 3)),
            contacts=feet_touching,
            base_contact=base_touching[:, 0],
            thigh_contacts=thighs_touching,
            knees=xp.reshape(field["knees"], (n, 4, 3)),
        )


def _field_split(fields: dict[str, slice], width: int) -> tuple[tuple[str | None, ...], tuple[int, ...]]:
    """The names and widths of the consecutive pieces of a block of ``width`` columns that hold ``fields`` (name ->
    its columns), the columns between them as unnamed pieces (None), for :func:`~margin_rl.arrays.split_columns`.

    Raises:
        ValueError: two fields share columns (the model's layout is not the one this reader was written for).
    """
    names: list[str | None] = []
    widths: list[int] = []
    at = 0
    for name, columns in sorted(fields.items(), key=lambda item: item[1].start):
        if columns.start < at:
            raise ValueError(f"the state field {name!r} (columns {columns.start}:{columns.stop}) overlaps another")
        if columns.start > at:
            names.append(None)
            widths.append(columns.start - at)
        names.append(name)
        widths.append(columns.stop - columns.start)
        at = columns.stop
    if width > at:
        names.append(None)
        widths.append(width - at)
    return tuple(names), tuple(widths)
