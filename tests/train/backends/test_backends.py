"""The SB3 and rsl-rl adapters over AnymalCore and their public factories, the episode metrics, the config
(de)serialisation."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from rsl_rl.runners import OnPolicyRunner
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecCheckNan

import margin_rl.train
from margin_rl.envs.config import EnvConfig
from margin_rl.train.backends.rsl import RslVecEnv, make_rsl_env
from margin_rl.train.backends.sb3 import Sb3VecEnv, make_sb3_env
from margin_rl.train.config import (
    RslPPOConfig,
    Sb3PPOConfig,
    apply_overrides,
    from_dict,
    parse_assignments,
    to_dict,
)
from margin_rl.train.environments import env_config_for, make_core
from margin_rl.train.metrics import EpisodeStatistics, tensorboard_tags

SHORT = {"episode_length_s": 0.1}  # 5 policy steps


def _core(weights: str, num_envs: int = 4, seed: int = 0, **overrides: object):
    config = env_config_for("margin_rl/AnymalB-v1", {"margin_weights": weights, **SHORT, **overrides})
    return make_core(config, num_envs, seed)


def test_sb3_vec_env_shapes_and_terminal_observation(toy_weights: str) -> None:
    venv = Sb3VecEnv(_core(toy_weights))
    venv.seed(7)
    obs = venv.reset()
    assert obs.shape == (4, 48) and obs.dtype == np.float32 and venv.observation_space.contains(obs[0])
    assert venv.action_space.shape == (12,) and venv.get_attr("render_mode") == [None] * 4
    assert venv.env_is_wrapped(object) == [False] * 4
    checked = VecCheckNan(venv, raise_exception=True)
    rng = np.random.default_rng(0)
    dones_seen = 0
    for _ in range(6):
        obs, rewards, dones, infos = checked.step(rng.uniform(-1, 1, (4, 12)).astype(np.float32))
        assert obs.shape == (4, 48) and rewards.shape == (4,) and dones.dtype == bool and len(infos) == 4
        for done, info in zip(dones, infos, strict=True):
            if done:
                dones_seen += 1
                assert info["terminal_observation"].shape == (48,)
                assert "TimeLimit.truncated" in info and {"r", "l", "t"} <= set(info["episode"])
                assert "lin_acc_rms_x" in info["episode_metrics"]
            else:
                assert info == {}
    assert dones_seen >= 4  # every environment reached its 5-step limit (or fell)
    # A seed set before a reset makes the initial states reproducible.
    venv.seed(7)
    first = venv.reset()
    venv.seed(7)
    np.testing.assert_array_equal(first, venv.reset())


def test_sb3_timeout_is_truncation(toy_weights: str) -> None:
    venv = Sb3VecEnv(_core(toy_weights, num_envs=2))
    venv.reset()
    infos: list[dict] = []
    for _ in range(5):
        _, _, dones, infos = venv.step(np.zeros((2, 12), dtype=np.float32))
    assert dones.all()
    assert all(info["TimeLimit.truncated"] for info in infos)
    assert all(info["episode"]["l"] == 5 for info in infos)


def test_rsl_vec_env_groups_time_outs_and_logs(toy_weights: str) -> None:
    env = RslVecEnv(_core(toy_weights, privileged_observations=True))
    obs = env.get_observations()
    assert set(obs.keys()) == {"policy", "critic"} and obs["policy"].shape == (4, 48)
    assert env.num_actions == 12 and env.max_episode_length == 5 and isinstance(env.cfg, dict)
    env.episode_length_buf = torch.tensor([4, 0, 0, 0])  # as rsl-rl's init_at_random_ep_len does
    assert env.episode_length_buf.tolist() == [4, 0, 0, 0]
    obs, rewards, dones, extras = env.step(torch.zeros(4, 12))
    assert rewards.dtype == torch.float32 and rewards.shape == (4,)
    assert extras["time_outs"].tolist() == [True, False, False, False] and bool(dones[0])
    log = extras["log"]
    for term in env.core.config.reward_weights:  # every term of the preset, also those of weight 0
        assert f"Episode_Reward/{term}" in log
    for tag in ("Episode_Metrics/lin_acc_rms_x", "Episode_Metrics/ang_acc_peak_z", "Episode_Metrics/margin_mean",
                "Episode_Metrics/velocity_error_mean", "Episode_Metrics/stance_width_mean",
                "Episode_Termination/fell", "Step/margin_mean"):  # fmt: skip
        assert tag in log
    assert env.episode_length_buf[0] == 0  # reset in the same step


def test_episode_statistics_rms_peak_and_warmup() -> None:
    stats = EpisodeStatistics(num_envs=1, dt=0.02, warmup_steps=1)
    lin = [np.array([[10.0, 0, 0]]), np.array([[3.0, -4.0, 0]]), np.array([[-5.0, 0, 0]])]
    for k, acc in enumerate(lin):
        info = {
            "reward_velocity_tracking": np.array([0.25]),
            "margin": np.array([0.1 * (k - 1)]),
            "base_lin_acc": acc,
            "base_ang_acc": -acc,
            "base_lin_vel": np.array([[0.5, 0, 0]]),
            "velocity_error": np.array([0.25]),
            "stance_width": np.array([0.4]),
            "base_height": np.array([0.40 + 0.03 * k]),
            "touchdowns": np.array([float(k + 1)]),  # 6 touchdowns in the episode
            "edge_touchdowns": np.array([float(k == 1)]),  # one of them on an edge
            "joint_torque_sq": np.array([[9.0, 16.0, 0.0][k]]),  # mean over the joints of tau^2
            "torque_at_limit": np.array([float(k == 0)]),  # a joint at its limit on the first step
            "fell": np.array([float(k == 2)]),
            "diverged": np.array([0.0]),
        }
        out = stats.update(np.array([1.0]), info, np.array([k == 2]), np.array([False]))
    assert out["length"][0] == 3 and out["return"][0] == 3.0 and out["reward/velocity_tracking"][0] == 0.75
    assert out["lin_acc_rms_x"][0] == pytest.approx(np.sqrt((9 + 25) / 2))  # the first step is warm-up
    assert out["lin_acc_peak_x"][0] == 5.0 and out["lin_acc_peak_y"][0] == 4.0
    assert out["lin_acc_rms"][0] == pytest.approx(np.sqrt((25 + 25) / 2))
    assert out["margin_mean"][0] == pytest.approx(0.0) and out["margin_min"][0] == pytest.approx(-0.1)
    assert out["margin_negative_fraction"][0] == pytest.approx(1 / 3)
    assert out["torque_rms"][0] == pytest.approx(np.sqrt(25 / 3)) and out["torque_limit_fraction"][0] == 1 / 3
    assert "margin_reward_share" not in out  # no margin term in this reward
    assert out["base_height_mean"][0] == pytest.approx(0.43)  # every step, warm-up included
    assert out["edge_landing_fraction"][0] == pytest.approx(1 / 6)
    assert out["fell"][0] == 1.0 and out["timed_out"][0] == 0.0 and out["duration_s"][0] == pytest.approx(0.06)
    tags = tensorboard_tags(out)
    assert "Episode_Reward/velocity_tracking" in tags and "Episode_Termination/fell" in tags and "env" not in tags


def test_config_round_trip_and_overrides() -> None:
    config = EnvConfig(robot="anymal_b", margin_weight=0.3)
    assert from_dict(EnvConfig, to_dict(config)) == config
    changed = apply_overrides(config, {"command": {"forward_velocity": [0.5, 1.0]}, "margin": "none"})
    assert changed.command.forward_velocity == (0.5, 1.0) and changed.command.yaw_rate == (0.0, 0.0)
    assert changed.margin == "none" and changed.margin_weight == 0.3
    for ppo in (RslPPOConfig(), Sb3PPOConfig()):
        assert from_dict(type(ppo), to_dict(ppo)) == ppo
    assert apply_overrides(RslPPOConfig(), {"actor_hidden_dims": [64, 64]}).actor_hidden_dims == (64, 64)
    assert parse_assignments(["a=1", "b=x", 'c={"k": [1, 2]}'], "opt") == {"a": 1, "b": "x", "c": {"k": [1, 2]}}
    with pytest.raises(TypeError, match="unknown option"):
        apply_overrides(config, {"no_such_field": 1})
    with pytest.raises(ValueError, match="unknown environment id"):
        env_config_for("margin_rl/NoSuchRobot-v0")
    with pytest.raises(ValueError, match="not a margin_rl ANYmal environment"):
        env_config_for("CartPole-v1")


# ---------------------------------------------------------------------------------------------------------------------
# public factories for plain SB3 and rsl-rl
# ---------------------------------------------------------------------------------------------------------------------
def test_plain_sb3_ppo_learns_on_make_sb3_env(toy_weights: str) -> None:
    assert margin_rl.train.make_sb3_env is make_sb3_env  # re-exported by the package
    env = make_sb3_env("margin_rl/AnymalB-v1", 4, seed=0, margin_weights=toy_weights, margin_weight=0.2, **SHORT)
    assert isinstance(env, Sb3VecEnv) and env.num_envs == 4 and env.core.config.margin_weight == 0.2
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps == 256


def test_rsl_runner_constructs_on_make_rsl_env(toy_weights: str, tmp_path) -> None:
    assert margin_rl.train.make_rsl_env is make_rsl_env
    params = {"alive_bonus": 0.1}
    env = make_rsl_env("margin_rl/AnymalB-v1", 4, seed=0, margin_weights=toy_weights, reward_params=params, **SHORT)
    assert isinstance(env, RslVecEnv) and env.device == torch.device("cpu")
    assert env.core.config.reward_params.alive_bonus == 0.1
    runner = OnPolicyRunner(env, RslPPOConfig().runner_cfg(False, 50), log_dir=None, device="cpu")
    assert runner.env is env


@pytest.mark.parametrize("factory", [make_sb3_env, make_rsl_env])
def test_factories_name_what_is_wrong(factory, toy_weights: str) -> None:
    with pytest.raises(TypeError, match=r"unknown environment option\(s\) \['no_such_option'\].*reward_params"):
        factory("margin_rl/AnymalB-v1", 2, no_such_option=1)
    with pytest.raises(ValueError, match=r"'margin_rl/SLIPHopper-v0' is not a margin_rl ANYmal environment"):
        factory("margin_rl/SLIPHopper-v0", 2)  # the whole message: tests/train/test_other_environments.py
    with pytest.raises(ValueError, match="unknown environment id"):
        factory("margin_rl/NoSuchRobot-v0", 2)


def test_update_threads_hold_inside_the_update_only(toy_weights: str, tmp_path, monkeypatch) -> None:
    from rsl_rl.algorithms import PPO

    from margin_rl.train.backends.rsl import CheckpointingRunner
    from margin_rl.train.runs import RunHooks, torch_threads

    seen: list[int] = []
    update = PPO.update

    def spy(self, *args, **kwargs):
        seen.append(torch.get_num_threads())
        return update(self, *args, **kwargs)

    monkeypatch.setattr(PPO, "update", spy)
    env = make_rsl_env("margin_rl/AnymalB-v1", 4, seed=0, margin_weights=toy_weights, **SHORT)
    hooks = RunHooks(lambda: False, lambda steps, mean_return: None, lambda path, steps: None)
    cfg = RslPPOConfig(num_steps_per_env=4).runner_cfg(False, 50)
    with torch_threads(1):
        CheckpointingRunner(env, cfg, tmp_path / "a", "cpu", hooks, update_threads=2).learn(2)
        assert seen == [2, 2] and torch.get_num_threads() == 1  # two threads in the update, the caller's one after
        CheckpointingRunner(env, cfg, tmp_path / "b", "cpu", hooks).learn(1)
        assert seen[-1] == 1  # None: the caller's setting throughout


def test_sb3_update_threads_hold_inside_the_update_and_are_not_saved(toy_weights: str, tmp_path, monkeypatch) -> None:
    from stable_baselines3 import PPO

    from margin_rl.train.backends.sb3 import ThreadedPPO, make_model
    from margin_rl.train.config import Sb3PPOConfig
    from margin_rl.train.runs import torch_threads

    seen: list[int] = []
    update = PPO.train
    monkeypatch.setattr(PPO, "train", lambda self: (seen.append(torch.get_num_threads()), update(self))[1])
    venv = make_sb3_env("margin_rl/AnymalB-v1", 4, seed=0, margin_weights=toy_weights, **SHORT)
    model = make_model(venv, Sb3PPOConfig(n_steps=8), seed=0, device="cpu")
    model.update_threads = 2
    with torch_threads(1):
        model.learn(32)
        assert seen and set(seen) == {2} and torch.get_num_threads() == 1
    model.save(tmp_path / "model.zip")
    assert PPO.load(tmp_path / "model.zip", device="cpu").num_timesteps == model.num_timesteps  # an ordinary PPO zip
    assert ThreadedPPO.load(tmp_path / "model.zip", device="cpu").update_threads is None  # a setting, not saved
