"""MJCF models shipped with margin_rl as package data (``margin_rl.assets``).

``anymal/anymal_b.xml`` and ``anymal/anymal_c.xml`` are the single source of truth for the robots'
physical facts; ``anymal/scene_*.xml`` put them on flat ground. Load them with
:func:`margin_rl.load_robot` rather than by path.
"""
