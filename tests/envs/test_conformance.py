"""Conformance of the ANYmal environments with the stock clients: Gymnasium's and SB3's checkers, Gymnasium's
vector API (next-step and same-step autoreset against SyncVectorEnv, list seeds, rendering), and the passive
checker's warnings."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import margin_rl  # noqa: F401 - registers the ids
from margin_rl.envs.anymal import available_render_modes
from margin_rl.envs.config import RandomizationConfig, TerminationConfig

ENV_ID = "margin_rl/AnymalB-v1"
NO_NOISE = RandomizationConfig(reset_joint_noise=0.0, reset_velocity_noise=0.0)

# The only check_env warnings left: the observation bounds are ±inf on purpose. The entries are velocities
# and joint states with no physical bound short of the divergence check (|qvel| > 1e3), so finite bounds
# would be made up and violated by real states; Gymnasium's own MuJoCo robots (Ant, Humanoid) declare ±inf
# too, and the learners normalise observations empirically.
UNAVOIDABLE_CHECK_ENV_WARNINGS = {
    "A Box observation space minimum value is -infinity. This is probably too low.",
    "A Box observation space maximum value is infinity. This is probably too high.",
}

HEADLESS_SCRIPT = textwrap.dedent(
    """
    import os
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env
    import margin_rl
    from margin_rl.envs.anymal import DisplayUnavailableError

    env = gym.make("margin_rl/AnymalB-v1")
    check_env(env.unwrapped)  # the stock call: every declared render mode is built and rendered
    print("CHECK_ENV_PASSED", env.unwrapped.metadata["render_modes"])
    for display in (None, ":9999"):  # no display at all, then one that cannot be opened
        if display is not None:
            os.environ["DISPLAY"] = display
        try:
            gym.make("margin_rl/AnymalB-v1", render_mode="human").reset()
        except DisplayUnavailableError as exc:
            print("HUMAN_REFUSED", display, exc)
    """
)


def test_stock_check_env_with_render_check_passes_on_a_headless_machine() -> None:
    """Before the fix MuJoCo's viewer ended this process with status 1 (GLFW without a display)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.setdefault("MUJOCO_GL", "egl")
    env["GIT_PYTHON_REFRESH"] = "quiet"
    done = subprocess.run([sys.executable, "-c", HEADLESS_SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    output = done.stdout + done.stderr
    if done.returncode != 0 and "OpenGL platform library has not been loaded" in output:
        pytest.skip("no headless OpenGL here (install Mesa's EGL or OSMesa)")
    assert done.returncode == 0, output
    assert "CHECK_ENV_PASSED ['rgb_array']" in done.stdout
    refusals = [line for line in done.stdout.splitlines() if line.startswith("HUMAN_REFUSED")]
    assert len(refusals) == 2, output
    assert "neither DISPLAY nor WAYLAND_DISPLAY" in refusals[0] and "rgb_array" in refusals[0]
    assert "':9999'" in refusals[1]


def test_human_mode_is_offered_only_with_a_display(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform.startswith("linux"):
        assert available_render_modes() == ["rgb_array"]
        monkeypatch.setenv("DISPLAY", ":0")
        assert available_render_modes() == ["human", "rgb_array"]


def test_gymnasium_check_env_warns_only_about_the_unbounded_observations() -> None:
    env = gym.make(ENV_ID)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)  # rendering: the headless test above
    messages = {str(w.message).replace("\x1b[33mWARN: ", "").replace("\x1b[0m", "") for w in caught}
    assert messages == UNAVOIDABLE_CHECK_ENV_WARNINGS


def test_passive_checker_raises_no_warning() -> None:
    """gymnasium.make wraps the env in the PassiveEnvChecker: reset, step and render must not warn."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make(ENV_ID, render_mode="rgb_array", width=32, height=24)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        try:
            env.render()
        except Exception as exc:  # no OpenGL platform on this machine; the other checks still ran
            if "OpenGL" not in str(exc):
                raise
        env.close()
    assert [str(w.message) for w in caught] == []


def test_sb3_check_env_passes_without_warnings() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gym.make(ENV_ID).unwrapped, warn=True)
    assert [str(w.message) for w in caught] == []


def test_make_vec_autoreset_matches_gymnasium_same_step_semantics() -> None:
    """The batched env against Gymnasium's own SyncVectorEnv in SAME_STEP mode over single envs.

    Without reset noise every episode starts from the same state, so both sides see the same transitions;
    a high base-height bound ends some episodes by termination, the step limit the others by truncation.
    """
    n, limit = 3, 6
    options = dict(randomization=NO_NOISE, termination=TerminationConfig(min_base_height=0.505), margin="none")
    ours = gym.make_vec(ENV_ID, num_envs=n, max_episode_steps=limit, autoreset_mode=AutoresetMode.SAME_STEP, **options)
    reference = SyncVectorEnv(
        [lambda: gym.make(ENV_ID, max_episode_steps=limit, **options) for _ in range(n)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    assert ours.metadata["autoreset_mode"] == reference.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, _ = ours.reset(seed=0)
    ref_obs, _ = reference.reset(seed=0)
    np.testing.assert_array_equal(obs, ref_obs)
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for _ in range(3 * limit):
        actions = rng.uniform(-1, 1, (n, 12)) * np.array([[0.0], [1.0], [3.0]])  # still, lively, clipped
        obs, reward, terminated, truncated, infos = ours.step(actions)
        ref_obs, ref_reward, ref_terminated, ref_truncated, ref_infos = reference.step(actions)
        np.testing.assert_array_equal(obs, ref_obs)  # the reset observation where an episode ended
        np.testing.assert_allclose(reward, ref_reward, atol=1e-12)
        np.testing.assert_array_equal(terminated, ref_terminated)
        np.testing.assert_array_equal(truncated, ref_truncated)
        ends["terminated"] += int(terminated.sum())
        ends["truncated"] += int(truncated.sum())
        assert ("final_obs" in infos) == ("final_obs" in ref_infos)
        if "final_obs" not in infos:
            continue
        np.testing.assert_array_equal(infos["_final_obs"], ref_infos["_final_obs"])
        np.testing.assert_array_equal(infos["_final_info"], ref_infos["_final_info"])
        for i in np.nonzero(ref_infos["_final_obs"])[0]:
            np.testing.assert_array_equal(infos["final_obs"][i], ref_infos["final_obs"][i])
            for key, value in ref_infos["final_info"].items():
                if not key.startswith("_"):
                    np.testing.assert_allclose(np.asarray(infos["final_info"][key][i], float), value[i], atol=1e-12)
    assert ends["terminated"] > 0 and ends["truncated"] > 0  # both kinds of episode end were compared
    ours.close()
    reference.close()


@pytest.mark.parametrize("mode", [None, AutoresetMode.NEXT_STEP, "NextStep"])
def test_make_vec_autoreset_matches_gymnasium_next_step_semantics(mode: object) -> None:
    """The default mode: the step after an episode ended returns the reset observation, reward 0 and
    terminated = truncated = False, ignoring the action, exactly as Gymnasium's SyncVectorEnv in NEXT_STEP mode."""
    n, limit = 3, 6
    options = dict(randomization=NO_NOISE, termination=TerminationConfig(min_base_height=0.505), margin="none")
    mode_option = {} if mode is None else {"autoreset_mode": mode}
    ours = gym.make_vec(ENV_ID, num_envs=n, max_episode_steps=limit, **mode_option, **options)
    reference = SyncVectorEnv(
        [lambda: gym.make(ENV_ID, max_episode_steps=limit, **options) for _ in range(n)],
        autoreset_mode=AutoresetMode.NEXT_STEP,
    )
    assert ours.metadata["autoreset_mode"] == reference.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, _ = ours.reset(seed=0)
    np.testing.assert_array_equal(obs, reference.reset(seed=0)[0])
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0, "resets": 0}
    for _ in range(3 * limit):
        actions = rng.uniform(-1, 1, (n, 12)) * np.array([[0.0], [1.0], [3.0]])
        obs, reward, terminated, truncated, infos = ours.step(actions)
        ref_obs, ref_reward, ref_terminated, ref_truncated, ref_infos = reference.step(actions)
        np.testing.assert_array_equal(obs, ref_obs)
        np.testing.assert_allclose(reward, ref_reward, atol=1e-12)
        np.testing.assert_array_equal(terminated, ref_terminated)
        np.testing.assert_array_equal(truncated, ref_truncated)
        assert "final_obs" not in infos and "final_obs" not in ref_infos
        np.testing.assert_array_equal(infos["_margin"], ref_infos["_margin"])  # masked out where reset
        ends["terminated"] += int(terminated.sum())
        ends["truncated"] += int(truncated.sum())
        ends["resets"] += int((~infos["_margin"]).sum())
    assert ends["terminated"] > 0 and ends["truncated"] > 0 and ends["resets"] > 0
    ours.close()
    reference.close()


def test_vector_reset_accepts_a_list_of_seeds_as_gymnasium_does() -> None:
    noisy = RandomizationConfig(observation_noise=1.0)
    vec = gym.make_vec(ENV_ID, num_envs=4, margin="none", randomization=noisy)
    by_int = vec.reset(seed=7)[0]
    np.testing.assert_array_equal(vec.reset(seed=[7, 8, 9, 10])[0], by_int)  # Gymnasium: s means [s, s+1, ...]
    by_list = vec.reset(seed=[0, 5, 0, 5])[0]
    np.testing.assert_array_equal(vec.reset(seed=(0, 5, 0, 5))[0], by_list)  # reproducible
    assert not np.array_equal(vec.reset(seed=[0, 5, 0, 6])[0], by_list)  # every entry matters
    vec.reset(seed=[None] * 4)
    with pytest.raises(ValueError, match="one seed per environment"):
        vec.reset(seed=[0, 1, 2])
    with pytest.raises(ValueError, match="mixes None and ints"):
        vec.reset(seed=[0, None, 2, 3])
    with pytest.raises(gym.error.Error, match=r"seed\[1\] must be an int >= 0"):
        vec.reset(seed=[0, -1, 2, 3])
    with pytest.raises(ValueError, match=r"seed\[1\] must be an int >= 0"):  # a ValueError too
        vec.reset(seed=[0, -1, 2, 3])


def test_vector_render_returns_one_frame_per_environment() -> None:
    vec = gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array", width=32, height=24, margin="none")
    vec.reset(seed=0)
    vec.step(np.zeros((2, 12)))
    try:
        frames = vec.render()
    except Exception as exc:
        if "OpenGL" in str(exc):
            pytest.skip(f"no headless OpenGL here ({exc}); set MUJOCO_GL=egl or osmesa")
        raise
    assert isinstance(frames, tuple) and len(frames) == 2
    for frame in frames:
        assert frame.shape == (24, 32, 3) and frame.dtype == np.uint8 and frame.std() > 0
    assert vec.metadata["render_fps"] == 50
    with pytest.raises(ValueError, match="render one environment"):
        gym.make_vec(ENV_ID, num_envs=2, render_mode="human", margin="none")
    vec.close()
