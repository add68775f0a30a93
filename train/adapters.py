"""Deprecated: the learner adapters moved, split by concern. Every name still imports from here, with a
DeprecationWarning naming its new module:

* :mod:`margin_rl.train.environments`: registered ids, ``EnvConfig``/constructor-keyword introspection, the
  environment interface (``env_config_for``, ``env_kwargs_for``, ``make_core``, ``make_gym_env``, ...);
* :mod:`margin_rl.train.sb3_backend`: ``Sb3VecEnv``, ``Sb3GymVecEnv``, ``make_gym_vec_env``,
  ``EpisodeMetricsSource`` (and the new ``make_sb3_env``);
* :mod:`margin_rl.train.rsl_backend`: ``RslVecEnv`` (and the new ``make_rsl_env``);
* :mod:`margin_rl.train.metrics`: ``InfoEpisodeStatistics``, ``SB3_INFO_KEYS``.
"""

from __future__ import annotations

from margin_rl.train.compat import moved

_ENVIRONMENTS = "margin_rl.train.environments"
_SB3 = "margin_rl.train.sb3_backend"
_RSL = "margin_rl.train.rsl_backend"
_METRICS = "margin_rl.train.metrics"

_MOVED = {
    **dict.fromkeys(
        (
            "ACTION_SIZE",
            "GENERIC_STEP_LIMIT",
            "MAKE_KEYWORDS",
            "MARGIN_WEIGHT_KEYWORD",
            "NAMESPACE",
            "RESERVED_KEYWORDS",
            "VECTOR_ENTRY_POINT",
            "check_gym_env",
            "check_margin_available",
            "env_config_for",
            "env_keyword",
            "env_keywords",
            "env_kwargs_for",
            "is_batched_anymal",
            "make_core",
            "make_gym_env",
            "margin_rl_ids",
            "margin_weight_of",
            "observation_size",
            "registered_spec",
            "takes_keyword",
        ),
        _ENVIRONMENTS,
    ),
    **dict.fromkeys(("EpisodeMetricsSource", "Sb3GymVecEnv", "Sb3VecEnv", "make_gym_vec_env"), _SB3),
    "RslVecEnv": _RSL,
    **dict.fromkeys(("InfoEpisodeStatistics", "SB3_INFO_KEYS"), _METRICS),
}

__getattr__ = moved(__name__, _MOVED)
