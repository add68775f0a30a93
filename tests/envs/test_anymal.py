"""ANYmal environments: Gymnasium API, reward sum, determinism, batch = single, lambda from the sim."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import margin_rl
from margin_rl.envs import ANYMAL_ENV_IDS, EPISODE_STEPS
from margin_rl.envs.config import CommandConfig, EnvConfig, RandomizationConfig, TerminationConfig
from margin_rl.envs.core import AnymalCore, heading_rotation, lambda_from_simulation
from margin_rl.envs.observations import POLICY_OBSERVATIONS, observation_size
from margin_rl.envs.terrain import STEP_EDGE_RISE
from margin_rl.robot import quat_wxyz_to_matrix
from margin_rl.robot.mjcf_names import BASE_QUATERNION_QPOS, JOINT_QVEL
from margin_rl.stability.analytic.lambda_state import from_lambda
from tests.stability.learned.test_model import random_weights

NO_NOISE = RandomizationConfig(reset_joint_noise=0.0, reset_velocity_noise=0.0)


@pytest.fixture(scope="module")
def toy_weights(tmp_path_factory: pytest.TempPathFactory) -> str:
    from margin_rl.stability.learned.model import save_weights

    path = tmp_path_factory.mktemp("w") / "toy"
    save_weights(random_weights(), path, {"robot": "toy"})
    return str(path.with_suffix(".npz"))


def native_vec(env_id: str, num_envs: int, **options: object) -> gym.vector.VectorEnv:
    """The native batched vector env of ``env_id`` (its ``vector_entry_point``)."""
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **options)


@pytest.mark.parametrize("env_id", sorted(ANYMAL_ENV_IDS))
def test_check_env_on_every_id(env_id: str, toy_weights: str) -> None:
    env = gym.make(env_id, margin_weights=toy_weights)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.unwrapped.core.max_episode_steps == EPISODE_STEPS  # the env truncates itself (no TimeLimit)
    assert sum(env.unwrapped.observation_structure.values()) == env.observation_space.shape[0]
    env.close()


def test_reward_is_the_sum_of_the_terms(toy_weights: str) -> None:
    env = gym.make("margin_rl/AnymalB-v1", reward_preset="shaped", margin_weights=toy_weights)
    env.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(100):
        _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 12))
        terms = [v for k, v in info.items() if k.startswith("reward_")]
        assert len(terms) == 12
        assert reward == pytest.approx(sum(terms), abs=1e-9)
        for key in ("margin", "base_lin_acc", "base_ang_acc", "contacts", "stance_width"):
            assert key in info
        if terminated or truncated:
            env.reset()


def test_paper_preset_has_exactly_two_terms(toy_weights: str) -> None:
    env = gym.make("margin_rl/AnymalC-v1", margin_weights=toy_weights, margin_weight=0.3)
    env.reset(seed=0)
    _, _reward, _, _, info = env.step(np.zeros(12))
    terms = {k: v for k, v in info.items() if k.startswith("reward_")}
    assert set(terms) == {"reward_velocity_tracking", "reward_margin"}
    assert terms["reward_margin"] == pytest.approx(0.3 * info["margin"])
    # L(8 (0.75 - v)): the logistic kernel of the heading velocity in the base frame.
    v = info["base_lin_vel"][0]
    x = 8.0 * (0.75 - v)
    assert terms["reward_velocity_tracking"] == pytest.approx(1.0 / (np.exp(-x) + 2 + np.exp(x)))


def test_alive_bonus_adds_a_constant_per_step_and_rejects_bad_values(toy_weights: str) -> None:
    rewards = {}
    for bonus in (0.0, 0.2):
        env = gym.make(
            "margin_rl/AnymalB-v1", margin_weights=toy_weights, margin_weight=0.3, reward_params={"alive_bonus": bonus}
        )
        env.reset(seed=4)
        _, rewards[bonus], _, _, info = env.step(np.full(12, 0.1))
    assert info["reward_alive"] == pytest.approx(0.2)
    assert rewards[0.2] - rewards[0.0] == pytest.approx(0.2, abs=1e-9)  # same seed, same step: only the bonus
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="alive_bonus"):
            gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, reward_params={"alive_bonus": bad})


def test_same_seed_same_rollout(toy_weights: str) -> None:
    def rollout(seed: int) -> np.ndarray:
        env = gym.make(
            "margin_rl/AnymalC-v1",
            margin_weights=toy_weights,
            randomization=RandomizationConfig(observation_noise=1.0, friction=(0.4, 1.0)),
        )
        obs, _ = env.reset(seed=seed)
        out = [obs]
        rng = np.random.default_rng(0)
        for _ in range(30):
            out.append(env.step(rng.uniform(-1, 1, 12))[0])
        return np.array(out)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.array_equal(rollout(3), rollout(4))


def test_batched_env_equals_single_envs_step_for_step(toy_weights: str) -> None:
    n = 3
    vec = native_vec("margin_rl/AnymalB-v1", n, margin_weights=toy_weights, randomization=NO_NOISE)
    singles = [gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, randomization=NO_NOISE) for _ in range(n)]
    obs_v, _ = vec.reset(seed=0)
    obs_s = [env.reset(seed=0)[0] for env in singles]
    np.testing.assert_array_equal(obs_v, np.array(obs_s))
    rng = np.random.default_rng(2)
    for _ in range(40):
        actions = rng.uniform(-0.5, 0.5, (n, 12))
        obs_v, rew_v, term_v, _, info_v = vec.step(actions)
        for i, env in enumerate(singles):
            obs, rew, _term, _, info = env.step(actions[i])
            if term_v[i]:
                continue
            # The physics is bit-identical (mujoco.batch); the learned margin runs in float32, where the
            # GEMM's rounding depends on the batch size, so margins and rewards agree to float32 precision.
            np.testing.assert_array_equal(obs_v[i], obs)
            assert rew_v[i] == pytest.approx(rew, abs=1e-6)
            assert info_v["margin"][i] == pytest.approx(info["margin"], abs=1e-6)


def test_lambda_from_a_known_state_matches_a_hand_computation() -> None:
    """Yawed, pitched base: e_g is the third row of R; vectors are rotated by the heading yaw only."""
    yaw, pitch = np.deg2rad(30.0), np.deg2rad(10.0)
    quat = np.zeros(4)
    qz, qy = np.zeros(4), np.zeros(4)
    mujoco.mju_axisAngle2Quat(qz, np.array([0, 0, 1.0]), yaw)
    mujoco.mju_axisAngle2Quat(qy, np.array([0, 1.0, 0]), pitch)
    mujoco.mju_mulQuat(quat, qz, qy)
    R = quat_wxyz_to_matrix(quat)[None]
    com = np.array([[1.0, 2.0, 0.5]])
    feet = com[:, None, :] + np.array([[[0.4, 0.3, -0.5], [0.4, -0.3, -0.5], [-0.4, 0.3, -0.5], [-0.4, -0.3, -0.5]]])
    com_vel = np.array([[np.cos(yaw), np.sin(yaw), 0.0]])  # 1 m/s along the heading
    lam = lambda_from_simulation(
        R,
        com,
        com_vel,
        np.zeros((1, 3)),
        np.zeros((1, 3)),
        np.array([[0.0, 10.0, 0.0]]),
        np.zeros((1, 3)),
        feet,
        np.array([0.7]),
        np.ones((1, 4)),
        np.tile([0, 0, 1.0], (1, 4, 1)),
    )
    st = from_lambda(lam[0])
    # Hand computation: e_g = (-sin pitch, 0, cos pitch); heading velocity (1, 0, 0) in H; feet rotated by -yaw.
    np.testing.assert_allclose(st.gravity_axis, [-np.sin(pitch), 0.0, np.cos(pitch)], atol=1e-12)
    np.testing.assert_allclose(st.com_vel, [1.0, 0.0, 0.0], atol=1e-12)
    c, s = np.cos(-yaw), np.sin(-yaw)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(st.feet, (feet[0] - com[0]) @ rot.T, atol=1e-12)
    np.testing.assert_allclose(st.ext_force, rot @ [0.0, 10.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(st.normals, np.tile([0, 0, 1.0], (4, 1)), atol=1e-12)
    assert st.mu == pytest.approx(0.7) and st.contacts.tolist() == [1, 1, 1, 1]
    np.testing.assert_allclose(heading_rotation(R)[0], rot.T, atol=1e-12)


def test_standing_robot_has_a_positive_analytic_margin() -> None:
    env = gym.make("margin_rl/AnymalC-v1", margin="analytic", randomization=NO_NOISE)
    env.reset(seed=0)
    for _ in range(50):  # 1 s: the robot settles from its 2 cm spawn drop
        _, _, terminated, _, info = env.step(np.zeros(12))
        assert not terminated
    assert info["margin"] > 0.1
    assert info["contacts"].tolist() == [1.0, 1.0, 1.0, 1.0]
    # The sim's lambda is a kinematically reachable state with the robot's standing feet.
    lam = env.unwrapped.core.last_lambda[0]
    st = from_lambda(lam)
    assert np.all(st.feet[:, 2] < -0.4) and abs(st.com_vel).max() < 0.02


def test_actions_nan_raise_and_out_of_range_are_clipped(toy_weights: str) -> None:
    env_a = gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, randomization=NO_NOISE)
    env_b = gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, randomization=NO_NOISE)
    env_a.reset(seed=0)
    env_b.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env_a.step(np.full(12, np.nan))
    big = np.full(12, 5.0)
    np.testing.assert_array_equal(env_a.step(big)[0], env_b.step(np.ones(12))[0])


def test_diverging_simulation_terminates_with_a_flag(toy_weights: str) -> None:
    env = gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights)
    env.reset(seed=0)
    core: AnymalCore = env.unwrapped.core
    core.physics.qvel[0, JOINT_QVEL] = 1e9  # an exploding state
    _, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"] == 1.0 and np.isfinite(reward)


def test_a_simulation_mujoco_resets_after_a_blow_up_is_reported_and_ends_as_diverged() -> None:
    """MuJoCo resets a simulation whose accelerations blow up (a "bad QACC" warning, no error) and steps on: the
    host backend reports it (by its cleared controls, or its clock that did not advance by the step) and the core
    ends its episode as diverged, the others stepping on; also in an episode's first step, from clock 0, where the
    reset leaves the clock as it was. The force is put on a thigh (the core rewrites the base's row every step)."""
    core = AnymalCore(EnvConfig(robot="anymal_c", margin="none"), 4, seed=0)
    thigh = core.physics.body_id("LF_THIGH")
    for first_step in (True, False):
        core.reset(seed=0)
        if not first_step:
            core.step(np.zeros((4, 12)))  # a clock past the reset's 0
        core.physics.xfrc_applied[2, thigh, 2] = 1e13  # [N]: an acceleration beyond MuJoCo's limit
        out = core.step(np.zeros((4, 12)))
        assert out.info["diverged"].tolist() == [0.0, 0.0, 1.0, 0.0] and out.terminated.tolist() == [0, 0, 1, 0]
    physics = core.physics
    for clue in ("controls", "clock"):  # the backend's own report, the ids, by either clue alone
        core.reset(seed=0)
        if clue == "clock":
            core.step(np.zeros((4, 12)))  # a clock past 0
            physics.ctrl[2] = 0.0  # controls a reset does not change
        physics.xfrc_applied[2, thigh, 2] = 1e13
        assert physics.step(4).tolist() == [2]


def test_vector_env_same_step_autoreset(toy_weights: str) -> None:
    vec = native_vec(
        "margin_rl/AnymalB-v1", 4, margin_weights=toy_weights, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
    )
    assert vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    vec.unwrapped.core.max_episode_steps = 3
    vec.reset(seed=0)
    for _ in range(2):
        infos = vec.step(np.zeros((4, 12)))[4]
        assert "final_obs" not in infos
    obs, _, _term, trunc, infos = vec.step(np.zeros((4, 12)))
    assert trunc.all() and infos["_final_obs"].all()
    assert infos["final_obs"][0].shape == (observation_size(),)
    assert vec.unwrapped.core.episode_step.tolist() == [0, 0, 0, 0]  # reset inside the step
    assert obs.shape == (4, observation_size())


def test_privileged_observation_and_structure(toy_weights: str) -> None:
    vec = native_vec("margin_rl/AnymalC-Rough-v1", 2, margin_weights=toy_weights, privileged_observations=True)
    vec.reset(seed=0)
    priv = vec.unwrapped.core.privileged_observation()
    assert priv.shape == (2, 38) and np.all(np.isfinite(priv))
    assert [t.name for t in POLICY_OBSERVATIONS][:3] == ["base_lin_vel", "base_ang_vel", "projected_gravity"]


def test_rough_terrain_heights_match_mujoco_collision_geometry() -> None:
    core = AnymalCore(EnvConfig(robot="anymal_c", terrain="rough", margin="none"), num_envs=1, seed=0)
    data = mujoco.MjData(core.model)
    mujoco.mj_forward(core.model, data)
    rng = np.random.default_rng(0)
    res, origin = core.terrain.resolution, core.terrain.origin
    # At grid nodes the heightfield surface and the bilinear query coincide.
    nodes = rng.integers(10, core.terrain.heights.shape[0] - 10, size=(40, 2))
    geomid = np.array([-1], dtype=np.int32)
    for r, c in nodes:
        x, y = origin[0] + c * res, origin[1] + r * res
        dist = mujoco.mj_ray(core.model, data, np.array([x, y, 3.0]), np.array([0, 0, -1.0]), None, 1, -1, geomid)
        assert 3.0 - dist == pytest.approx(core.terrain.height(np.array([x, y])), abs=2e-3)
    heights = core.terrain.heights
    assert np.ptp(heights) >= 0.06 and np.isfinite(heights).all()


def test_edge_touchdowns_are_feet_landing_where_the_ground_under_the_sole_rises() -> None:
    """Robots dropped over the rough tiles and stepped with lively random targets: each step's ``touchdowns`` and
    ``edge_touchdowns`` equal a recount from MuJoCo's own state (the foot geoms' positions and the foot contact
    sensors in an independent MjData, the terrain's spread under a sole of the MJCF's foot radius); some landings are
    on edges, and none is on flat ground."""
    n = 8
    core = AnymalCore(EnvConfig(robot="anymal_c", terrain="rough", margin="none", randomization=NO_NOISE), n, 0)
    core.reset()
    rng = np.random.default_rng(1)
    inner = (core.terrain.heights.shape[1] - 1) * core.terrain.resolution / 2 - 16.0
    xy = rng.uniform(-inner, inner, (n, 2))
    core.physics.qpos[:, 0:2] = xy
    core.physics.qpos[:, 2] = core.terrain.height(xy) + 0.6
    core.physics.forward()
    feet = [mujoco.mj_name2id(core.model, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot") for leg in ("LF", "RF", "LH", "RH")]
    sensors = [core.model.sensor(f"{leg}_foot_contact") for leg in ("LF", "RF", "LH", "RH")]
    radius = core.model.geom_size[feet[0], 0]
    core.step(np.zeros((n, 12)))  # the core's contacts of the step before, as the recount's
    before = np.array([[core.render_data(env).sensordata[s.adr[0]] > 0 for s in sensors] for env in range(n)])
    edges = 0
    for _ in range(40):
        out = core.step(rng.uniform(-1, 1, (n, 12)))
        for env in range(n):
            data = core.render_data(env)
            touching = np.array([data.sensordata[s.adr[0]] > 0 for s in sensors])
            landing = touching & ~before[env]
            spread = core.terrain.height_spread(data.geom_xpos[feet, :2], radius)
            assert out.info["touchdowns"][env] == landing.sum()
            assert out.info["edge_touchdowns"][env] == (landing & (spread > STEP_EDGE_RISE)).sum()
            before[env] = touching
        edges += int(out.info["edge_touchdowns"].sum())
        if out.terminated.any() or out.truncated.any():
            break
    assert edges > 0
    flat = AnymalCore(EnvConfig(robot="anymal_c", margin="none"), 2, 0)
    flat.reset()
    for _ in range(20):
        out = flat.step(rng.uniform(-1, 1, (2, 12)))
        assert not out.info["edge_touchdowns"].any()


def test_vertical_margin_normals_change_only_the_normals_lambda_carries(toy_weights: str) -> None:
    """``margin_normals="vertical"``: the same robots dropped over the rough tiles with the same actions as with the
    terrain's normals, so the same physics; lambda differs in its normals alone, which are (0, 0, 1) for every foot,
    while the terrain's tilt under some feet; and the margin is the network's on the terrain run's lambda with its
    normals set upright (an independent evaluation)."""
    from margin_rl.envs.core import MARGIN_CLIP
    from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES
    from margin_rl.stability.learned.model import LearnedMargin

    n = 6
    config = EnvConfig(robot="anymal_c", terrain="rough", margin_weights=toy_weights, randomization=NO_NOISE)
    cores = [AnymalCore(config.replace(margin_normals=kind), n, seed=0) for kind in ("terrain", "vertical")]
    xy = np.random.default_rng(2).uniform(-8.0, 8.0, (n, 2))  # off the flat spawn pads
    for core in cores:
        core.reset()
        core.physics.qpos[:, 0:2] = xy
        core.physics.qpos[:, 2] = core.terrain.height(xy) + 0.6
        core.physics.forward()
    rng = np.random.default_rng(3)
    normals = LAMBDA_SLICES["normals"]
    others = np.ones(47, dtype=bool)
    others[normals] = False
    tilted = 0
    network = LearnedMargin.load(toy_weights)
    for _ in range(30):
        action = rng.uniform(-1, 1, (n, 12))
        terrain_out, vertical_out = (core.step(action) for core in cores)
        terrain_lam, vertical_lam = (core.last_lambda for core in cores)
        np.testing.assert_array_equal(terrain_lam[:, others], vertical_lam[:, others])
        np.testing.assert_array_equal(vertical_lam[:, normals], np.tile([0.0, 0.0, 1.0], (n, 4)))
        tilted += int((terrain_lam[:, normals].reshape(n, 4, 3)[..., 2] < np.cos(np.radians(1.0))).sum())
        upright = terrain_lam.copy()
        upright[:, normals] = np.tile([0.0, 0.0, 1.0], (n, 4))
        expected = np.clip(network(upright), *MARGIN_CLIP)
        np.testing.assert_allclose(vertical_out.info["margin"], expected, rtol=1e-5, atol=1e-6)
        if terrain_out.terminated.any() or terrain_out.truncated.any():
            break
    assert tilted > 0


@pytest.mark.parametrize("value", ["upright", None, 1])
def test_unknown_margin_normals_are_named(value: object) -> None:
    with pytest.raises(ValueError, match=r"EnvConfig\.margin_normals must be one of \['terrain', 'vertical'\]"):
        EnvConfig(margin_normals=value)


def test_unknown_option_is_named() -> None:
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'margin_wieght'.*margin_weight"):
        gym.make("margin_rl/AnymalB-v1", margin_wieght=1.0)


@pytest.mark.parametrize("make", [gym.make, lambda env_id, **kw: gym.make_vec(env_id, num_envs=2, **kw)])
def test_an_unknown_keyword_is_refused_in_pythons_own_words(make) -> None:
    """Worded as Python's TypeError for an unexpected keyword (clients probe optional keywords by that message
    and retry without them), then the valid fields."""
    pattern = r"^Anymal(Vector)?Env\.__init__\(\) got an unexpected keyword argument 'unknown'; .*margin_weight"
    with pytest.raises(TypeError, match=pattern):
        make("margin_rl/AnymalB-v1", unknown=1)
    with pytest.raises(TypeError, match=r"got an unexpected keyword argument 'also' \(and \['unknown'\]\)"):
        make("margin_rl/AnymalB-v1", unknown=1, also=2)
    with pytest.raises(ValueError, match="margin must be"):
        gym.make("margin_rl/AnymalB-v1", margin="magic")


def test_env_ids_are_registered_on_import() -> None:
    assert margin_rl.envs.ANYMAL_ENV_IDS
    for env_id in ANYMAL_ENV_IDS:
        assert env_id in gym.registry


def test_rgb_render(toy_weights: str, tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    env = gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, render_mode="rgb_array", width=64, height=48)
    env.reset(seed=0)
    try:
        frame = env.render()
    except Exception as exc:  # no OpenGL platform on this machine
        pytest.skip(f"no headless OpenGL here ({exc}); set MUJOCO_GL=egl or osmesa")
    assert frame.shape == (48, 64, 3) and frame.std() > 0


def test_fwp_factor_as_the_margin_term() -> None:
    env = gym.make("margin_rl/AnymalC-v1", margin="fwp", randomization=NO_NOISE)
    env.reset(seed=0)
    for _ in range(20):
        info = env.step(np.zeros(12))[4]
    assert 0.0 < info["margin"] <= 1.0  # standing: strictly inside the feasible wrench polytope
    assert info["reward_margin"] == pytest.approx(info["margin"])


def test_diverged_state_does_not_crash_the_analytic_margin_mode() -> None:
    env = gym.make("margin_rl/AnymalB-v1", margin="analytic")
    env.reset(seed=0)
    env.unwrapped.core.physics.qvel[0, :] = np.nan
    _, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"] == 1.0 and np.isfinite(reward)


@pytest.mark.parametrize("vector", [False, True])
def test_episode_length_option_is_the_episode_the_agent_sees(vector: bool, toy_weights: str) -> None:
    """A changed episode_length_s is not overridden by a registered TimeLimit (there is none)."""
    options = {"margin_weights": toy_weights, "episode_length_s": 0.2, "randomization": NO_NOISE}  # 10 steps
    if vector:
        env = gym.make_vec("margin_rl/AnymalB-v1", num_envs=2, **options)
        actions = np.zeros((2, 12))
    else:
        env = gym.make("margin_rl/AnymalB-v1", **options)
        actions = np.zeros(12)
    env.reset(seed=0)
    for step in range(1, 11):
        _, _, terminated, truncated, _ = env.step(actions)
        assert not np.any(terminated)
        assert np.all(truncated) == (step == 10) and np.any(truncated) == (step == 10)
    env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_info_lambda_is_the_state_the_margin_saw(vector: bool, toy_weights: str) -> None:
    """info["lambda"] is the core's lambda; decoded, it gives the info's contacts and stance width back."""
    from margin_rl.stability import LAMBDA_DIM, lambda_names
    from margin_rl.stability.learned.model import LearnedMargin

    options = {"margin_weights": toy_weights, "randomization": RandomizationConfig(push_interval_s=0.1)}
    env = (
        gym.make_vec("margin_rl/AnymalB-v1", num_envs=3, **options)
        if vector
        else gym.make("margin_rl/AnymalB-v1", **options)
    )
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    model = LearnedMargin.load(toy_weights)
    for _ in range(20):
        _, _, _, _, info = env.step(rng.uniform(-0.5, 0.5, size=env.action_space.shape))
        lam = np.atleast_2d(info["lambda"])
        assert lam.shape == (3 if vector else 1, LAMBDA_DIM) == (lam.shape[0], len(lambda_names()))
        np.testing.assert_array_equal(lam, env.unwrapped.core.last_lambda)
        state = from_lambda(lam)
        np.testing.assert_array_equal(state.contacts, np.atleast_2d(info["contacts"]))
        feet = state.feet
        width = 0.5 * (np.abs(feet[:, 0, 1] - feet[:, 1, 1]) + np.abs(feet[:, 2, 1] - feet[:, 3, 1]))
        np.testing.assert_allclose(width, np.atleast_1d(info["stance_width"]), rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.clip(model(lam), -0.5, 0.5), np.atleast_1d(info["margin"]), atol=1e-12)
        np.testing.assert_array_equal(state.to_lambda(), lam)  # to_lambda(from_lambda(lam)) == lam
    env.close()


def test_analytic_kind_gives_a_flight_phase_the_extended_margin_not_the_floor() -> None:
    """In the air there is no Feasible Region; the analytic kind rates the state with m_x (stability.extended)."""
    from margin_rl.envs.core import MARGIN_CLIP
    from margin_rl.stability.analytic.extended import extended_margin

    env = gym.make("margin_rl/AnymalC-v1", margin="analytic", randomization=NO_NOISE)
    env.reset(seed=0)
    core = env.unwrapped.core
    core.physics.qpos[0, 2] += 1.0  # 1 m up: no foot in contact for the next few steps
    info = env.step(np.zeros(12))[4]
    assert info["contacts"].tolist() == [0.0, 0.0, 0.0, 0.0]
    expected = extended_margin(core.robot, core.last_lambda[0])
    assert info["margin"] == pytest.approx(expected)
    assert MARGIN_CLIP[0] < info["margin"] < 0.0


def test_acceleration_filter_smooths_lambda_not_the_measured_accelerations(toy_weights: str) -> None:
    """lambda's CoM acceleration is the EMA of the finite difference; the info reports the difference itself."""
    from margin_rl.stability.analytic.lambda_state import LAMBDA_SLICES

    envs = [
        gym.make("margin_rl/AnymalB-v1", margin_weights=toy_weights, randomization=NO_NOISE, acceleration_filter=f)
        for f in (0.0, 0.5)
    ]
    for env in envs:
        env.reset(seed=0)
    rng = np.random.default_rng(0)
    filtered = np.zeros(3)
    for _ in range(6):
        action = rng.uniform(-1, 1, 12)
        raw_info, ema_info = (env.step(action)[4] for env in envs)
        np.testing.assert_allclose(ema_info["base_lin_acc"], raw_info["base_lin_acc"], atol=1e-12)
        # The EMA runs in the world frame; lambda holds it in the heading frame H (same z, a yaw apart).
        raw_acc = envs[0].unwrapped.core.last_lambda[0, LAMBDA_SLICES["com_acc"]]
        ema_acc = envs[1].unwrapped.core.last_lambda[0, LAMBDA_SLICES["com_acc"]]
        filtered = 0.5 * filtered + 0.5 * raw_acc[2]
        assert ema_acc[2] == pytest.approx(filtered, abs=1e-9)
    assert not np.allclose(ema_acc, raw_acc)


def test_knee_clearance_term_matches_the_shank_bodies_in_mujoco(toy_weights: str) -> None:
    """The term is sum_i max(0, h_c - z_knee,i), z_knee the SHANK body origin (the KFE joint) read from an
    independent mj_forward of the same state; off by default."""
    config = EnvConfig(robot="anymal_b", margin_weights=toy_weights, randomization=NO_NOISE)
    off = AnymalCore(config, 1, seed=0)
    off.reset()
    assert "reward_knee_clearance" not in off.step(np.zeros((1, 12))).info

    clearance = 0.35  # above the standing knees (about 0.28 m), so every knee counts
    core = AnymalCore(config.replace(reward_params={"knee_clearance": 2.0, "knee_clearance_height": clearance}), 2, 0)
    core.reset()
    for _ in range(5):
        out = core.step(np.zeros((2, 12)))
    for env in range(2):
        data = core.render_data(env)
        knees = np.array([data.body(f"{leg}_SHANK").xpos[2] for leg in core.robot.leg_names])
        expected = -2.0 * np.sum(np.maximum(clearance - knees, 0.0))
        assert expected < -0.1
        np.testing.assert_allclose(out.info["reward_knee_clearance"][env], expected, rtol=0, atol=1e-9)


def _base_subtree_velocity(core: AnymalCore, env: int) -> np.ndarray:
    """The robot's CoM velocity [m/s] (the base body's subtree) from an independent mj_forward of ``env``'s state."""
    data = core.render_data(env)
    return data.subtree_linvel[mujoco.mj_name2id(core.physics.model, mujoco.mjtObj.mjOBJ_BODY, "base")].copy()


def test_base_acceleration_term_is_the_metrics_acceleration(toy_weights: str) -> None:
    """The control's penalty is -K |a|^2 of the unfiltered CoM acceleration the comparison's lin_acc_rms averages
    (reported in the base frame: the norm is the same), and that acceleration is the finite difference of MuJoCo's
    subtree CoM velocity over the policy step, read independently; off by default."""
    config = EnvConfig(robot="anymal_b", margin_weights=toy_weights, randomization=NO_NOISE)
    off = AnymalCore(config, 1, seed=0)
    off.reset()
    assert "reward_base_acceleration" not in off.step(np.zeros((1, 12))).info
    core = AnymalCore(config.replace(reward_params={"base_acceleration": 0.01}), 2, 0)
    core.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (2, 12))
    for _ in range(3):
        before = [_base_subtree_velocity(core, env) for env in range(2)]
        out = core.step(actions)
    after = [_base_subtree_velocity(core, env) for env in range(2)]
    for env in range(2):
        acc = (after[env] - before[env]) / core.dt
        assert np.linalg.norm(acc) > 0.1  # a moving robot, not a vacuous zero
        np.testing.assert_allclose(out.info["base_lin_acc"][env] @ out.info["base_lin_acc"][env], acc @ acc, rtol=1e-6)
        np.testing.assert_allclose(out.info["reward_base_acceleration"][env], -0.01 * (acc @ acc), rtol=1e-6)


def test_torque_info_reads_the_actuators_against_the_mjcf_forceranges(toy_weights: str) -> None:
    """``joint_torque_sq`` is the mean over the joints of the actuator forces squared, ``torque_at_limit`` 1 where one
    of them reaches its MJCF forcerange (read here from MuJoCo's model by actuator): never while standing still,
    on most steps of full-scale alternating actions."""
    config = EnvConfig(robot="anymal_c", margin_weights=toy_weights, randomization=NO_NOISE, action_scale=2.0)
    core = AnymalCore(config, 2, seed=0)
    core.reset()
    model = core.physics.model
    limits = np.array([model.actuator(i).forcerange[1] for i in range(model.nu)])
    standing = core.step(np.zeros((2, 12)))
    assert not standing.info["torque_at_limit"].any()
    at_limit = []
    for k in range(10):
        out = core.step(np.full((2, 12), (-1.0) ** k))
        forces = np.asarray(core.physics.actuator_force)
        np.testing.assert_allclose(out.info["joint_torque_sq"], np.mean(forces**2, axis=1), rtol=1e-12)
        expected = np.any(np.abs(forces) >= limits * (1 - 1e-4), axis=1)
        np.testing.assert_array_equal(out.info["torque_at_limit"], expected.astype(float))
        at_limit.append(expected)
    assert np.mean(at_limit) > 0.5


def test_base_height_term_matches_the_base_body_in_mujoco(toy_weights: str) -> None:
    """The term is max(0, f h_standing - z_base), h_standing read from the MJCF's standing keyframe independently
    of the environment (model.key_qpos) and z_base from an independent mj_forward of the same state; the step's
    info reports the height either way, and the term is off by default."""
    config = EnvConfig(robot="anymal_b", margin_weights=toy_weights, randomization=NO_NOISE)
    off = AnymalCore(config, 1, seed=0)
    off.reset()
    assert "reward_base_height" not in off.step(np.zeros((1, 12))).info

    fraction = 1.2  # above the standing base, so the term is active at once
    core = AnymalCore(config.replace(reward_params={"base_height": 3.0, "base_height_fraction": fraction}), 2, 0)
    core.reset()
    key = mujoco.mj_name2id(core.model, mujoco.mjtObj.mjOBJ_KEY, "standing")
    standing_height = core.model.key_qpos[key, 2]  # flat floor at z = 0
    for _ in range(5):
        out = core.step(np.zeros((2, 12)))
    for env in range(2):
        base_z = core.render_data(env).body("base").xpos[2]
        np.testing.assert_allclose(out.info["base_height"][env], base_z, rtol=0, atol=1e-9)
        expected = -3.0 * max(fraction * standing_height - base_z, 0.0)
        assert expected < -0.05
        np.testing.assert_allclose(out.info["reward_base_height"][env], expected, rtol=0, atol=1e-9)


def test_termination_penalty_costs_exactly_the_falls() -> None:
    """Two cores stepped with the same actions from the same seed, one with the penalty: their rewards differ by
    -penalty on the steps whose info says ``fell`` (the terminated steps here: a base-height bound just below the
    standing base ends episodes early, with autoreset) and nowhere else; the term is off by default."""
    options = dict(
        robot="anymal_b", margin="none", randomization=NO_NOISE, termination=TerminationConfig(min_base_height=0.505)
    )
    off = AnymalCore(EnvConfig(**options), 3, seed=0)
    on = AnymalCore(EnvConfig(**options, reward_params={"termination_penalty": 10.0}), 3, seed=0)
    off.reset(), on.reset()
    rng = np.random.default_rng(0)
    falls = 0
    for _ in range(12):
        actions = rng.uniform(-1, 1, (3, 12)) * np.array([[0.0], [1.0], [3.0]])
        a, b = off.step(actions), on.step(actions)
        assert "reward_termination" not in a.info
        np.testing.assert_array_equal(a.terminated, b.terminated)
        fell = b.info["fell"].astype(bool)
        np.testing.assert_array_equal(fell, b.terminated)  # no diverged simulation here
        np.testing.assert_allclose(b.info["reward_termination"], -10.0 * fell, rtol=0, atol=0)
        np.testing.assert_allclose(b.reward - a.reward, -10.0 * fell, rtol=0, atol=1e-12)
        falls += int(fell.sum())
    assert falls > 0  # the bound does end episodes, so the comparison above saw the term at work


def test_yaw_tracking_is_the_kernel_of_the_yaw_rate_error() -> None:
    """The term by hand: L(gain (omega_cmd - omega_z)) times its weight, from the base's angular velocity in its own
    frame (MuJoCo's free-joint qvel[3:6]); a yaw command of 0.3 rad/s against a robot stepped with random actions;
    off by default."""
    options = dict(robot="anymal_b", margin="none", randomization=NO_NOISE,
                   command=CommandConfig(forward_velocity=(0.5, 0.5), yaw_rate=(0.3, 0.3)))  # fmt: skip
    off = AnymalCore(EnvConfig(**options), 2, seed=0)
    on = AnymalCore(EnvConfig(**options, reward_params={"yaw_tracking": 0.5}), 2, seed=0)
    off.reset(), on.reset()
    rng = np.random.default_rng(1)
    for _ in range(5):
        actions = rng.uniform(-1, 1, (2, 12))
        a, b = off.step(actions), on.step(actions)
        assert "reward_yaw_tracking" not in a.info
        yaw_rate = on.physics.qvel[:, 5]  # free joint: angular velocity in the body frame
        x = 8.0 * (0.3 - yaw_rate)
        expected = 0.5 / (np.exp(-x) + 2.0 + np.exp(x))
        np.testing.assert_allclose(b.info["reward_yaw_tracking"], expected, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(b.reward - a.reward, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("termination_penalty", -1.0),
        ("termination_penalty", np.inf),
        ("yaw_tracking", -0.5),
        ("yaw_tracking", np.nan),
        ("knee_clearance", -1.0),
        ("knee_clearance_height", -0.1),
        ("knee_clearance", np.nan),
        ("base_height", -1.0),
        ("base_height_fraction", 0.0),
        ("base_height_fraction", 2.0),
    ],
)
def test_reward_params_reject_bad_values(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        EnvConfig(reward_params={field: value})


def test_push_in_the_air_changes_the_momentum_by_the_impulse(toy_weights: str) -> None:
    """A heading-frame push of the robot held high above the floor (no contacts): the horizontal CoM velocity
    changes by J / m_total along the heading axis turned to the world, and lambda's f_ext is the push on every
    step it acts (the last one too)."""
    config = EnvConfig(robot="anymal_b", margin_weights=toy_weights, randomization=NO_NOISE)
    core = AnymalCore(config, 2, seed=0)
    core.reset()
    yaw = np.array([0.0, 0.7])
    core.physics.qpos[:, 2] += 20.0  # far above the floor for the whole test
    core.physics.qpos[:, BASE_QUATERNION_QPOS] = np.column_stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)])
    core.physics.qvel[:] = 0.0
    core.physics.forward()
    mass = mujoco.mj_getTotalmass(core.model)
    force = np.array([[60.0, 0.0, 0.0], [0.0, -45.0, 0.0]])  # heading frame [N]
    duration = 0.1
    steps = core.push_steps(duration)
    assert steps == 5
    com_vel_before = core._read().com_vel.copy()
    heading_at_push = heading_rotation(quat_wxyz_to_matrix(core.physics.qpos[:, BASE_QUATERNION_QPOS]))
    core.push(np.arange(2), force, duration, frame="heading")
    for _ in range(steps):
        out = core.step(np.zeros((2, 12)))
        ext = from_lambda(out.info["lambda"]).ext_force
        np.testing.assert_allclose(ext, force, atol=1e-2)  # H = heading frame (the legs' servo motion turns
        # the base by a few microradians in the air)
    out = core.step(np.zeros((2, 12)))
    np.testing.assert_array_equal(from_lambda(out.info["lambda"]).ext_force, 0.0)
    dv = core._read().com_vel - com_vel_before
    impulse = np.einsum("nij,nj->ni", heading_at_push, force) * steps * core.dt
    # measured agreement: 1.5e-4 relative (the implicit integrator), bound at 1e-3
    np.testing.assert_allclose(dv[:, :2], impulse[:, :2] / mass, rtol=1e-3, atol=1e-5)


def test_push_rejects_bad_input(toy_weights: str) -> None:
    core = AnymalCore(EnvConfig(robot="anymal_b", margin_weights=toy_weights), 2, seed=0)
    core.reset()
    with pytest.raises(ValueError, match="shape"):
        core.push(np.arange(2), np.zeros((1, 3)), 0.1)
    with pytest.raises(ValueError, match="finite"):
        core.push(np.arange(1), np.array([[np.nan, 0, 0]]), 0.1)
    with pytest.raises(ValueError, match="ids"):
        core.push(np.array([5]), np.zeros((1, 3)), 0.1)
    with pytest.raises(ValueError, match="duration"):
        core.push(np.arange(1), np.zeros((1, 3)), 0.0)
    with pytest.raises(ValueError, match="frame"):
        core.push(np.arange(1), np.zeros((1, 3)), 0.1, frame="base")
