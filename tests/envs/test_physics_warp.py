"""The MuJoCo Warp backend on Warp's CPU device against ``mujoco.batch``: the written contract, one decimated step
at a time from the same MuJoCo state (flat and rough, pushes, resets, randomised friction and mass), whole rollouts
by their distributions, the buffer overflow, the refusals, copies.

Without mujoco-warp these tests skip, except under CI (``CI=true``), where ``make test`` installs the ``gpu`` extra
and a missing package is a failure.
"""

from __future__ import annotations

import copy
import inspect
import pickle

import gymnasium as gym
import numpy as np
import pytest
import torch

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.arrays import TorchRandom, like, to_numpy, uniform_columns
from margin_rl.envs.backends import make_physics
from margin_rl.envs.config import EnvConfig, RandomizationConfig
from margin_rl.envs.core import AnymalCore
from margin_rl.envs.physics import MujocoBatchPhysics, PhysicsBackend
from margin_rl.stability import lambda_names
from tests.conftest import require_mujoco_warp

require_mujoco_warp()

from margin_rl.envs.physics_warp import PhysicsOverflowError, WarpPhysics, contact_budget  # noqa: E402

WARP_CPU = {"physics": "warp", "physics_device": "cpu"}
N = 8
RANDOMISED = RandomizationConfig(friction=(0.4, 1.0), added_base_mass=(-5.0, 5.0), push_interval_s=0.1)
"""Per-world friction and base mass (the batched model fields), and a push started every few steps."""

# Flat ground: Warp computes in float32 (eps 1.2e-7), MuJoCo in float64. One decimated step (4 physics steps) from
# the same state, measured over 3 x 12 steps of 8 worlds: qpos 5.4e-7, qvel 5.9e-5, lambda 1.2e-3 (its accelerations
# are velocity differences divided by dt = 0.02 s), margin and reward 2.6e-6, observations 1.2e-5, terminations equal.
# The tolerances leave about ten times that.
FLAT = {"qpos": 1e-5, "qvel": 1e-3, "lambda": 0.01, "margin": 5e-5, "reward": 5e-5, "observation": 2e-4}


class _HostDrawsAsTensors:
    """numpy's draws answered as tensors: the Warp core's generator in the parity tests, so that both cores draw the
    same numbers (pushes, noise, resets) from one state."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def uniform(self, *args: object, **kwargs: object) -> torch.Tensor:
        return torch.as_tensor(self.rng.uniform(*args, **kwargs))

    def integers(self, *args: object, **kwargs: object) -> torch.Tensor:
        return torch.as_tensor(self.rng.integers(*args, **kwargs))

    def exponential(self, *args: object, **kwargs: object) -> torch.Tensor:
        return torch.as_tensor(self.rng.exponential(*args, **kwargs))

    def uniform_columns(self, n: int, bounds: tuple) -> list[torch.Tensor]:
        return [torch.as_tensor(a) for a in uniform_columns(self.rng, n, bounds)]


def _mirror(source: AnymalCore, target: AnymalCore) -> None:
    """Give ``target`` (another backend) ``source``'s whole state: physics rows, per-world fields, and the core's
    own (random generator, filters, commands, pushes, counters), as pickling does between backends; the arrays as
    the target's tensors."""
    target.physics.set_state(source.physics.get_state())
    for name in AnymalCore._STATE:
        value = copy.deepcopy(getattr(source, name))
        if name == "rng":
            value = _HostDrawsAsTensors(value)
        elif isinstance(value, np.ndarray):  # into the target's buffer: its state lives at fixed addresses
            getattr(target, name)[...] = like(value, target.physics.qpos)
            continue
        setattr(target, name, value)


def _pair(terrain: str, **options: object) -> tuple[AnymalCore, AnymalCore]:
    """A mujoco.batch core and a Warp one of the same config; the reference steps as a device does (sync_free: a draw
    per environment for pushes and autoresets, resets by mask), so that mirrored generators draw the same numbers."""
    config = EnvConfig(robot="anymal_c", terrain=terrain, randomization=RANDOMISED, **options)
    reference = AnymalCore(config, num_envs=N, seed=3)
    reference.sync_free = True
    warp = AnymalCore(config, num_envs=N, seed=3, **WARP_CPU)
    assert warp.sync_free
    reference.reset(seed=11)
    return reference, warp


def test_both_backends_satisfy_the_written_contract() -> None:
    """Every member of :class:`PhysicsBackend`, with the same parameters, on both backends; live arrays of the
    documented shapes."""
    reference, warp = _pair("flat")
    members = [n for n in vars(PhysicsBackend) if not n.startswith("_")]
    for backend in (reference.physics, warp.physics):
        for name in [*members, *PhysicsBackend.__annotations__]:
            assert hasattr(backend, name), f"{type(backend).__name__} lacks {name}"
        for name in members:
            declared = getattr(PhysicsBackend, name)
            if callable(declared):
                expected = list(inspect.signature(declared).parameters)
                assert list(inspect.signature(getattr(type(backend), name)).parameters) == expected, name
        model = backend.model
        assert backend.qpos.shape == (N, model.nq) and backend.qvel.shape == (N, model.nv)
        assert backend.xfrc_applied.shape == (N, model.nbody, 6) and backend.time.shape == (N,)
        assert backend.sensordata.shape == (N, model.nsensordata) and backend.site_xpos.shape == (N, model.nsite, 3)
        assert backend.per_env_field("geom_friction").shape == (N, model.ngeom, 3)
        assert backend.per_env_field("body_mass").shape == (N, model.nbody)


def _steps_from_the_same_state(terrain: str, steps: int, seed: int):
    """(reference, warp, expected, got) after each policy step, the Warp core re-seeded from MuJoCo's whole state
    before every step; random actions, pushes (random, per world) and a reset of two worlds half way."""
    reference, warp = _pair(terrain)
    rng = np.random.default_rng(seed)
    for k in range(steps):
        if k == steps // 2:  # a reset of some worlds, the same random draws in both
            reference.reset(np.array([1, 4]))
        _mirror(reference, warp)
        if k == steps // 2:  # the reset worlds' clocks restart, the others' run on (float32 time)
            np.testing.assert_array_equal(to_numpy(warp.physics.time)[[1, 4]], 0.0)
            np.testing.assert_allclose(to_numpy(warp.physics.time), reference.physics.time, rtol=1e-6)
        actions = rng.uniform(-0.5, 0.5, size=(N, 12))
        expected, got = reference.step(actions), warp.step(actions)
        assert isinstance(got.reward, torch.Tensor)  # the Warp core answers in the physics' tensors
        yield reference, warp, expected, got.to_numpy()


def test_a_reset_restores_the_keyframes_controls_and_clears_the_applied_forces() -> None:
    """What the core leaves to the backends' reset (it writes only qpos and qvel after one): the reset worlds' ctrl is
    the keyframe's, their applied forces 0 and their clock the keyframe's, by ids and by mask; the other worlds keep
    theirs."""
    reference, warp = _pair("flat")
    for backend in (reference.physics, warp.physics):
        key = backend.model.key(reference._key)
        for rows in (np.array([1, 4]), np.isin(np.arange(N), [1, 4])):
            backend.ctrl[:] = like(np.full((N, backend.model.nu), 0.25), backend.ctrl)
            backend.xfrc_applied[:] = 7.0
            backend.time[:] = 3.0
            backend.reset(rows if isinstance(backend, MujocoBatchPhysics) else like(rows, backend.qpos), reference._key)
            reset = np.isin(np.arange(N), [1, 4])
            ctrl, xfrc, time = (to_numpy(a) for a in (backend.ctrl, backend.xfrc_applied, backend.time))
            np.testing.assert_allclose(ctrl[reset], np.broadcast_to(key.ctrl, (2, backend.model.nu)), rtol=1e-6)
            assert (ctrl[~reset] == 0.25).all()
            assert (xfrc[reset] == 0.0).all() and (xfrc[~reset] == 7.0).all()
            assert (time[reset] == key.time[0]).all() and (time[~reset] == 3.0).all()


def test_one_decimated_step_at_a_time_matches_mujoco_on_flat_ground() -> None:
    """Every step's physics, lambda, margin, rewards, observations and terminations within :data:`FLAT`."""
    pushed = 0
    for reference, warp, expected, got in _steps_from_the_same_state("flat", steps=12, seed=0):
        pushed += int(np.count_nonzero(reference._push_applied[:, 0]))
        for name in ("qpos", "qvel"):
            diff = np.abs(to_numpy(getattr(warp.physics, name)) - getattr(reference.physics, name)).max()
            assert diff < FLAT[name], (name, diff)
        np.testing.assert_allclose(got.info["lambda"], expected.info["lambda"], atol=FLAT["lambda"])
        np.testing.assert_allclose(got.info["margin"], expected.info["margin"], atol=FLAT["margin"])
        np.testing.assert_allclose(got.reward, expected.reward, atol=FLAT["reward"])
        np.testing.assert_allclose(got.observation, expected.observation, atol=FLAT["observation"])
        np.testing.assert_array_equal(got.terminated, expected.terminated)
    assert pushed > 0, "no push was applied: the comparison did not cover xfrc_applied"


def test_one_decimated_step_at_a_time_matches_mujoco_on_the_heightfield() -> None:
    """On the heightfield the two collision pipelines give different contact sets (several points per foot sphere
    where it straddles prism edges), so a foot can touch in one backend and not yet in the other. Measured over
    384 world-steps (4 x 12 steps of 8 worlds): contact flags differed in 5 (1.3 %), and there the margin moved by
    0.30-0.37 m (another support region); where they agreed, the margin differed by 3e-4 m (median), 7.6e-3 (95th
    percentile), 2.7e-2 (max); qpos per world 4.7e-4 / 5.9e-3 / 3.2e-2 m. Checked here with about twice that room,
    by their distribution over the world-steps, not step by step."""
    contacts = [i for i, n in enumerate(lambda_names()) if n.startswith("contacts.")]
    agree, margin, reward, qpos, terminated_equal = [], [], [], [], []
    for reference, warp, expected, got in _steps_from_the_same_state("rough", steps=24, seed=1):
        same = np.all(got.info["lambda"][:, contacts] == expected.info["lambda"][:, contacts], axis=1)
        agree.extend(same)
        margin.extend(np.abs(got.info["margin"] - expected.info["margin"])[same])
        reward.extend(np.abs(got.reward - expected.reward)[same])
        qpos.extend(np.abs(to_numpy(warp.physics.qpos) - reference.physics.qpos).max(axis=1))
        terminated_equal.extend(got.terminated == expected.terminated)
    assert np.mean(agree) >= 0.95
    assert np.percentile(margin, 95) < 0.02 and max(margin) < 0.06  # [m]
    assert np.percentile(reward, 95) < 0.02
    assert np.percentile(qpos, 95) < 0.015 and max(qpos) < 0.06  # [m]
    assert np.mean(terminated_equal) >= 0.98


def test_per_world_fields_reach_the_physics() -> None:
    """Friction and base mass written per world change that world's dynamics on Warp as on MuJoCo."""
    reference, warp = _pair("flat")
    warp.reset(seed=11)
    masses = to_numpy(warp.physics.per_env_field("body_mass"))
    assert np.ptp(masses[:, warp._base]) > 1.0  # the randomisation drew different masses (the core's own draws)
    _mirror(reference, warp)  # MuJoCo's fields and generator: the resets below draw the same numbers in both
    reference.reset()
    warp.reset()
    np.testing.assert_allclose(
        to_numpy(warp.physics.per_env_field("body_mass")), reference.physics.per_env_field("body_mass"), rtol=1e-6
    )
    np.testing.assert_allclose(to_numpy(warp.mu), reference.mu)
    floor = to_numpy(warp.physics.per_env_field("geom_friction"))[:, warp._floor, 0]
    np.testing.assert_allclose(
        floor, reference.physics.per_env_field("geom_friction")[:, reference._floor, 0], rtol=1e-6
    )
    assert np.ptp(floor) > 0.1


def test_rollouts_agree_in_distribution() -> None:
    """Whole rollouts (not step by step: trajectories part after contact events) of a walking gait, zero actions
    from the standing pose on flat ground, 60 steps: no falls on either backend, the same mean forward velocity
    and margin within what float32 trajectories drift apart by."""
    config = EnvConfig(robot="anymal_c", terrain="flat")
    runs = {}
    for name, options in (("mujoco", {}), ("warp", WARP_CPU)):
        core = AnymalCore(config, num_envs=N, seed=5, **options)
        core.reset(seed=5)
        velocities, margins, falls = [], [], 0
        for _ in range(60):
            out = core.step(np.zeros((N, 12))).to_numpy()
            velocities.append(out.info["base_lin_vel"][:, 0])
            margins.append(out.info["margin"])
            falls += int(out.info["fell"].sum())
        runs[name] = (np.mean(velocities), np.mean(margins), falls)
    (v_ref, m_ref, f_ref), (v_warp, m_warp, f_warp) = runs["mujoco"], runs["warp"]
    assert f_ref == f_warp == 0
    assert abs(v_warp - v_ref) < 0.01  # [m/s]
    assert abs(m_warp - m_ref) < 0.005  # [m]


def test_overflow_is_an_error_naming_the_setting_to_raise() -> None:
    config = EnvConfig(robot="anymal_c", terrain="flat")
    core = AnymalCore(config, num_envs=2, seed=0, physics_options={"nconmax": 1, "njmax": 4}, **WARP_CPU)
    core.reset(seed=0)
    with pytest.raises(PhysicsOverflowError, match=r"nconmax=1 .*njmax=4.*raise them"):
        for _ in range(10):  # the robots spawn 2 cm above the ground: contacts begin when the feet land
            core.step(np.zeros((2, 12)))


def test_contact_budget_rule() -> None:
    """nconmax: colliding robot geoms x contacts per geom (1 on a plane, 4 on a heightfield); njmax: 4 rows per
    contact plus the limited joints; both rounded up to 8 (see contact_budget)."""
    flat = AnymalCore(EnvConfig(robot="anymal_c"), num_envs=1).model
    rough = AnymalCore(EnvConfig(robot="anymal_c", terrain="rough"), num_envs=1).model
    (ncon_flat, nj_flat), (ncon_rough, nj_rough) = contact_budget(flat), contact_budget(rough)
    assert ncon_rough >= 4 * (ncon_flat - 7) and nj_rough > nj_flat
    assert nj_flat >= 4 * ncon_flat and ncon_flat % 8 == nj_flat % 8 == 0


def test_refusals_name_what_to_use() -> None:
    config = EnvConfig(robot="anymal_c")
    for kind in ("analytic", "fwp"):
        with pytest.raises(ValueError, match=rf"margin='{kind}'.*not offered with physics='warp'.*'learned'"):
            AnymalCore(config.replace(margin=kind), num_envs=1, **WARP_CPU)
    with pytest.raises(ValueError, match=r"physics must be one of \['mujoco', 'warp'\], got 'bullet'"):
        AnymalCore(config, num_envs=1, physics="bullet")
    with pytest.raises(ValueError, match="physics='mujoco' runs on the CPU"):
        AnymalCore(config, num_envs=1, physics_device="cuda:0")
    with pytest.raises(ValueError, match="physics_device must be one of Warp's devices"):
        AnymalCore(config, num_envs=1, physics="warp", physics_device="tpu")
    with pytest.raises(TypeError, match=r"physics_options \['nthread'\] are not settings of physics='warp'"):
        AnymalCore(config, num_envs=1, physics_options={"nthread": 2}, **WARP_CPU)
    with pytest.raises(ValueError, match="not a per-environment field of the Warp backend"):
        make_physics("warp", AnymalCore(config, num_envs=1).model, 1, "cpu").per_env_field("dof_damping")


def test_copies_step_to_the_same_numbers() -> None:
    """pickle and deepcopy of a Warp core: rebuilt on the same backend, stepping bit-identically (float32 rows)."""
    core = AnymalCore(EnvConfig(robot="anymal_c", randomization=RANDOMISED), num_envs=4, seed=2, **WARP_CPU)
    core.reset(seed=2)
    core.step(np.full((4, 12), 0.2))
    for make_copy in (lambda c: pickle.loads(pickle.dumps(c)), copy.deepcopy):
        copied = make_copy(core)
        assert isinstance(copied.physics, WarpPhysics)
        actions = np.full((4, 12), -0.1)
        a, b = core.step(actions).to_numpy(), copied.step(actions).to_numpy()
        np.testing.assert_array_equal(a.observation, b.observation)
        np.testing.assert_array_equal(a.reward, b.reward)
        core = copied


def test_gymnasium_ids_take_the_backend_as_construction_arguments() -> None:
    envs = gym.make_vec("margin_rl/AnymalC-v1", num_envs=2, **WARP_CPU)
    observations, _ = envs.reset(seed=0)
    assert observations.shape == (2, 48) and isinstance(envs.unwrapped.core.physics, WarpPhysics)
    envs.step(np.zeros((2, 12)))
    env = gym.make("margin_rl/AnymalB-v1", **WARP_CPU)
    env.reset(seed=0)
    assert isinstance(env.unwrapped.core.physics, WarpPhysics)
    assert isinstance(gym.make("margin_rl/AnymalB-v1").unwrapped.core.physics, MujocoBatchPhysics)


def test_a_short_rsl_training_on_the_warp_backend_is_reproducible() -> None:
    """rsl-rl PPO over make_rsl_env(physics="warp") on Warp's CPU device: two runs with one seed end with the same
    policy (Warp's CPU device is deterministic), and training moved it."""
    import torch
    from rsl_rl.runners import OnPolicyRunner

    from margin_rl.train import make_rsl_env
    from margin_rl.train.config import RslPPOConfig

    def train() -> tuple[torch.Tensor, torch.Tensor]:
        torch.manual_seed(0)
        env = make_rsl_env("margin_rl/AnymalC-v1", 4, seed=0, **WARP_CPU)
        assert isinstance(env.core.physics, WarpPhysics)
        runner = OnPolicyRunner(env, RslPPOConfig(num_steps_per_env=8).runner_cfg(False, 50), log_dir=None)
        before = torch.nn.utils.parameters_to_vector(runner.alg.actor.parameters()).detach().clone()
        runner.learn(num_learning_iterations=2)
        return before, torch.nn.utils.parameters_to_vector(runner.alg.actor.parameters()).detach()

    (start_a, end_a), (_, end_b) = train(), train()
    torch.testing.assert_close(end_a, end_b, rtol=0, atol=0)
    assert not torch.equal(start_a, end_a)


def test_the_warp_core_keeps_its_whole_state_on_the_physics_device() -> None:
    """Beside Warp the core computes on the physics' tensors: after steps, pushes, randomised resets and an autoreset,
    every array of its state and of its outputs is a float64/bool/int64 tensor on that device, its generator a torch
    one; the Gymnasium edge gets numpy."""
    core = AnymalCore(EnvConfig(robot="anymal_c", randomization=RANDOMISED), num_envs=4, seed=1, **WARP_CPU)
    core.reset(seed=1)
    core.push(np.array([0, 2]), np.array([[60.0, 0.0, 0.0], [0.0, 60.0, 0.0]]), 0.1, frame="heading")
    for _ in range(5):
        out = core.step(torch.zeros(4, 12))
    core.episode_step[1] = core.max_episode_steps - 1  # environment 1 times out at the next step: autoreset
    out = core.step(torch.zeros(4, 12))
    assert bool(out.truncated[1]) and int(core.episode_step[1]) == 0
    assert isinstance(core.rng, TorchRandom)
    for name in AnymalCore._STATE:
        value = getattr(core, name)
        if name not in ("rng", "max_episode_steps"):
            assert isinstance(value, torch.Tensor) and value.device == core.physics.qpos.device, name
    arrays = [out.observation, out.reward, out.terminated, out.truncated, out.final_observation, *out.info.values()]
    assert all(isinstance(a, torch.Tensor) for a in arrays)
    assert out.observation.dtype == torch.float32 and out.reward.dtype == torch.float64
    host = out.to_numpy()
    assert isinstance(host.reward, np.ndarray) and all(isinstance(v, np.ndarray) for v in host.info.values())


def test_rsl_rl_gets_the_physics_tensors_without_a_copy() -> None:
    """make_rsl_env with the learner on the physics' device: the episode counter rsl-rl writes is the core's own
    tensor, and observations, rewards and dones are tensors on that device."""
    from margin_rl.train import make_rsl_env

    env = make_rsl_env("margin_rl/AnymalC-v1", 3, seed=0, device="cpu", **WARP_CPU)
    assert env.episode_length_buf.data_ptr() == env.core.episode_step.data_ptr()
    env.episode_length_buf = torch.tensor([5, 6, 7])
    assert env.core.episode_step.tolist() == [5, 6, 7]
    observations, rewards, dones, extras = env.step(torch.zeros(3, 12))
    assert observations["policy"].shape == (3, 48) and rewards.dtype == torch.float32 and dones.shape == (3,)
    assert extras["time_outs"].device == rewards.device == torch.device("cpu")


def test_an_overflow_between_two_device_checks_is_kept_until_the_next() -> None:
    """A device core reads the buffer flags once per check_every steps (the learner's rollout; the same on Warp's CPU
    device as on a GPU): an overflow in between is not lost, it is raised at the next check."""
    from margin_rl.envs.core import DEVICE_CHECK_STEPS

    config = EnvConfig(robot="anymal_c", terrain="flat")
    core = AnymalCore(config, num_envs=2, seed=0, physics_options={"nconmax": 1, "njmax": 4}, **WARP_CPU)
    core.check_every = DEVICE_CHECK_STEPS  # as the rsl-rl adapter sets it
    core.reset(seed=0)
    for _ in range(DEVICE_CHECK_STEPS - 1):  # the feet land within these steps: the buffers overflow
        core.step(np.zeros((2, 12)))
    assert int(core.physics._overflow_seen.max()) != 0  # recorded on the device, not yet read
    with pytest.raises(PhysicsOverflowError, match="nconmax=1"):
        core.step(np.zeros((2, 12)))


def test_the_height_scan_is_the_same_on_the_device() -> None:
    """The actor's height scan on the heightfield, computed by the Warp core on its tensors from MuJoCo's state, equals
    the mujoco.batch core's to float32 (the base pose is float32 in Warp: 2e-4 in the observation leaves ten times
    the measured difference)."""
    reference, warp = _pair("rough", height_scan=True)
    _mirror(reference, warp)
    expected, got = reference.observe_all(), to_numpy(warp.observe_all())
    assert got.shape == expected.shape and got.shape[1] > 48
    np.testing.assert_allclose(got[:, 48:], expected[:, 48:], atol=FLAT["observation"])
    assert np.ptp(expected[:, 48:]) > 0.1  # the scan saw the tiles' relief


def test_the_terrain_curriculum_runs_on_the_device() -> None:
    """Levels, the level rule and spawning by level on the Warp core's tensors equal the mujoco.batch core's, from
    the same state and the same draws: half the worlds carried 3 m (promoted), the others left standing (demoted);
    then both restart on given rows (a resumed training's)."""
    from margin_rl.envs.terrain import TerrainConfig

    curriculum = TerrainConfig(size=8.0, tile=4.0, border=0.0, curriculum_levels=4, initial_max_level=3)
    reference, warp = _pair("rough", terrain_config=curriculum)
    for _ in range(5):
        reference.step(np.zeros((N, 12)))
    reference.physics.qpos[::2, 0] += 3.0
    before = reference.terrain_level.copy()
    _mirror(reference, warp)
    reference.reset()
    warp.reset()
    assert isinstance(warp.terrain_level, torch.Tensor)
    np.testing.assert_array_equal(to_numpy(warp.terrain_level), reference.terrain_level)
    assert np.all(reference.terrain_level[1::2] == np.maximum(before[1::2] - 1, 0))  # demoted
    np.testing.assert_allclose(to_numpy(warp._spawn_xy), reference._spawn_xy)
    np.testing.assert_allclose(to_numpy(warp.physics.qpos)[:, :2], reference.physics.qpos[:, :2], atol=1e-6)
    # a resume's restart on saved rows (numpy rows into the device core, the same draws on both)
    rows = np.arange(N) % 4
    _mirror(reference, warp)
    reference.restart_on_levels(rows)
    warp.restart_on_levels(rows)
    np.testing.assert_array_equal(to_numpy(warp.terrain_level), rows)
    np.testing.assert_allclose(to_numpy(warp.physics.qpos)[:, :2], reference.physics.qpos[:, :2], atol=1e-6)
