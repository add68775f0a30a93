"""``python -m margin_rl.robot``: the report of the shipped robots (as ``margin-rl-robots``)."""

from margin_rl.robot.cli import main

raise SystemExit(main())
