"""Training, comparison and evaluation entry points of margin_rl, installed as ``margin_rl.train``.

PPO is never re-implemented here: rsl-rl's ``OnPolicyRunner`` and Stable-Baselines3's ``PPO`` do the learning,
on thin adapters over the one batched simulation :class:`margin_rl.envs.core.AnymalCore` (ANYmal ids), or,
for any other registered Gymnasium id (e.g. ``margin_rl/SLIPHopper-v0``), SB3 over ``gymnasium.make``.

Command-line entry points (``python -m margin_rl.train.<name> --help``):

* :mod:`~margin_rl.train.train`: one PPO run (``--backend rsl|sb3``), TensorBoard, checkpoints, ``--resume``;
* :mod:`~margin_rl.train.compare`: margin weight 0 vs > 0 over seeds, Fig. 9-style plot, table (PNG, MD, JSON);
  ``--bundle`` ships the policies with a card, ``--bundled`` evaluates shipped ones (the README's main job);
* :mod:`~margin_rl.train.evaluate`: deterministic episodes of a saved policy (SB3 zip, rsl-rl checkpoint,
  TorchScript): metrics JSON, plots, optional MP4.

Modules: :mod:`~margin_rl.train.config` (PPO settings per backend), :mod:`~margin_rl.train.adapters` (SB3 and
rsl-rl vector environments), :mod:`~margin_rl.train.metrics` (episode metrics shared by all of the above),
:mod:`~margin_rl.train.runs` (run directories, atomic writes, stop signals), :mod:`~margin_rl.train.policies`
(loading saved policies), :mod:`~margin_rl.train.bundle` (policy bundles and their cards),
:mod:`~margin_rl.train.rsl_backend` and :mod:`~margin_rl.train.sb3_backend`.
Importing this package imports neither torch nor the RL libraries.
"""
