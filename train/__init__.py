"""Training, comparison and evaluation entry points of margin_rl, installed as ``margin_rl.train``."""
