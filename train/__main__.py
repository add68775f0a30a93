"""``python -m margin_rl.train <command> [options]``: one entry for the commands of :mod:`margin_rl.train.commands`."""

from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "train": "margin_rl.train.commands.train",
    "evaluate": "margin_rl.train.commands.evaluate",
    "compare": "margin_rl.train.commands.compare",
    "push-recovery": "margin_rl.train.commands.push_recovery",
    "kernels": "margin_rl.train.commands.kernels",
}
"""Command name -> the module whose ``main(argv)`` runs it."""

USAGE = f"usage: python -m margin_rl.train {{{','.join(COMMANDS)}}} [options]   (<command> --help for its options)"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE)
        return 0 if argv else 2
    command = argv[0].replace("_", "-")
    if command not in COMMANDS:
        print(f"unknown command {argv[0]!r}; {USAGE}", file=sys.stderr)
        return 2
    return importlib.import_module(COMMANDS[command]).main(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
