"""The robot-agnostic geometry of the analytic margin: arrays in, arrays out; never imports ``margin_rl.robot``.

::

    contact         the geometric inputs of both criteria: ContactSet, LegLimits, CentroidalLoad, input checks,
                    tangent bases, the gravito-inertial wrench, Clarabel settings and statuses
    polygon         planar convex polygons: caps, hull, area, half-spaces (seed 000 eq. 6)
    projection      iterative projection of a convex planar set from its support oracle (Bretl & Lall, Alg. 1)
    region          the Feasible Region (derivation, solve_region, feasible_region), FeasibleRegion
    region_program  one state's conic program and its support oracle (one Clarabel solver per region)
    region_batch    the region's programs for many states of one stance, one solver structure reused
    icp             capture point (eq. 5) and the stability margin (eq. 7)
"""
