"""The two PPO learners on the batched ANYmal simulation: ``rsl`` (rsl-rl's OnPolicyRunner) and ``sb3``
(Stable-Baselines3's PPO), each with its vector-environment adapter, atomic checkpoints and exact resume.

Imported on first use only: each module loads torch and its RL library."""
