"""``python -m margin_rl``: the package's main job (for now, a report of the shipped robots)."""

from margin_rl.robot import main

raise SystemExit(main())
