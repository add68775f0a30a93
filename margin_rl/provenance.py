"""Provenance of produced artifacts (weights, policies, cards): the package commit they came from."""

from __future__ import annotations

import subprocess
from pathlib import Path


def git_commit() -> str:
    """``HEAD`` of the checkout this package runs from, marked when tracked files have uncommitted changes.

    Returns ``"unknown"`` for an installed wheel (no checkout) or when git is missing.
    """
    root = Path(__file__).resolve().parents[1]
    try:
        sha = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=True)
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return sha.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")
