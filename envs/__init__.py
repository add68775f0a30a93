"""Gymnasium environments of margin_rl, installed as ``margin_rl.envs``."""
