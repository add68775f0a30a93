"""The command lines of ``margin_rl.train``: ``train``, ``evaluate``, ``compare``, ``push_recovery`` and the
options they share (``options``). Run one as ``python -m margin_rl.train <command>``."""
