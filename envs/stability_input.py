"""lambda (seed 000 eq. 4) from world-frame simulator quantities: where the environments build it.

Frames: W is the world; H, the horizontal frame, has W's z axis and the yaw of the base heading (the
base x axis projected on the ground). lambda holds e_g, the third row of the base orientation R_WB,
and every other vector in H, the feet relative to the CoM. Accelerations: the environment passes the
CoM acceleration and the base angular acceleration as finite differences of the CoM velocity (subtree
sensor) and of the base angular velocity (world frame) over the 20 ms policy step, i.e. the mean
acceleration over the step, smoothed by the EMA a_k = f a_(k-1) + (1 - f) a_fd with f =
``EnvConfig.acceleration_filter`` (0.5 by default). Why this estimator (BENCHMARKS "Accelerations in lambda",
one trot, the three side by side): the finite difference *is* the mean of MuJoCo's substep accelerations, the
instantaneous value is dominated by touchdown impacts (1.4-1.5x the noise), and the filter halves the
step-to-step noise, so impact spikes do not drive the reward, at a lag of about one policy step.
"""

from __future__ import annotations

from typing import Any

from margin_rl.arrays import namespace, rotate, unstack
from margin_rl.stability.analytic.lambda_state import StabilityState


def heading_rotation(base_rotation: Any) -> Any:
    """Rotation R_WH (..., 3, 3) of the horizontal frame H in the world: the yaw of the base x axis (numpy arrays or
    torch tensors, :mod:`margin_rl.arrays`)."""
    xp = namespace(base_rotation)
    x_axis = base_rotation[..., 0]  # the base x axis in W (R_WB's first column)
    yaw = xp.atan2(x_axis[..., 1], x_axis[..., 0])
    c, s = xp.cos(yaw), xp.sin(yaw)
    zero, one = xp.zeros_like(c), xp.ones_like(c)
    entries = xp.stack([c, -s, zero, s, c, zero, zero, zero, one], axis=-1)  # row by row
    return xp.reshape(entries, (*entries.shape[:-1], 3, 3))


def stability_state_from_simulation(
    base_rotation: Any,
    com: Any,
    com_vel: Any,
    com_acc: Any,
    base_ang_acc: Any,
    ext_force: Any,
    ext_torque: Any,
    feet: Any,
    mu: Any,
    contacts: Any,
    normals: Any,
    heading: Any = None,
) -> StabilityState:
    """lambda's fields (N, ...) from world-frame simulator quantities (all (N, ...), world frame, SI units; all
    numpy arrays or all torch tensors).

    e_g is the third row of the base rotation R_WB; every other vector v is rotated into H as
    R_WH^T v, and the feet are taken relative to the CoM first: the 13 vectors of an environment in one batched
    product. ``heading``: R_WH where the caller has it already (:func:`heading_rotation` of ``base_rotation``).
    """
    xp = namespace(base_rotation)
    single = xp.stack([com_vel, com_acc, base_ang_acc, ext_force, ext_torque], axis=1)  # (N, 5, 3)
    vectors = xp.concat([single, feet - com[:, None, :], normals], axis=1)  # (N, 5 + 4 + 4, 3), world frame
    heading = heading_rotation(base_rotation) if heading is None else heading
    in_h = rotate(heading, vectors, inverse=True)
    com_vel_h, com_acc_h, base_ang_acc_h, ext_force_h, ext_torque_h = unstack(in_h)[:5]
    return StabilityState(
        gravity_axis=base_rotation[:, 2, :],
        com_vel=com_vel_h,
        com_acc=com_acc_h,
        base_ang_acc=base_ang_acc_h,
        ext_force=ext_force_h,
        ext_torque=ext_torque_h,
        feet=in_h[:, 5:9],
        mu=xp.astype(xp.asarray(mu), xp.float64, copy=False),
        contacts=xp.astype(xp.asarray(contacts), xp.float64),
        normals=in_h[:, 9:13],
    )


def lambda_from_simulation(*args: Any, **kwargs: Any) -> Any:
    """lambda (N, 47) from the arguments of :func:`stability_state_from_simulation`."""
    return stability_state_from_simulation(*args, **kwargs).to_lambda()


def stance_width(feet_h: Any) -> Any:
    """Mean lateral distance [m] between the left and right foot of the front and of the hind pair.

    ``feet_h`` (N, 4, 3): feet in H (LF, RF, LH, RH), e.g. :attr:`StabilityState.feet`.
    """
    xp = namespace(feet_h)
    lateral = feet_h[:, :, 1]
    left_minus_right = lateral[:, 0::2] - lateral[:, 1::2]  # (N, 2): the front pair, the hind pair
    return 0.5 * xp.sum(xp.abs(left_minus_right), axis=1)
