"""Evaluation of trained policies: ``episodes`` (the one deterministic episode runner and recorder),
``significance`` (difference, Welch test and bootstrap interval between two variants over seeds) and ``media``
(episode and comparison plots, videos)."""
