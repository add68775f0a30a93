"""lambda (seed 000 eq. 4) and the analytic margin of a robot's state: lambda -> IK -> region -> ICP -> m_a.

::

    lambda_state     LAMBDA_FIELDS, StabilityState, from_lambda: the one declaration of lambda's layout
    sampling         the Table I sampler (sample_states) and the locomotion distribution (DISTRIBUTIONS)
    contact_problem  ContactProblem: what both criteria need about N states (IK, Jacobians, contacts,
                     ICP, wrench), batch-first: one state is a batch of one
    margin           analytic_margin(robot, lam) and analytic_margin_batch (the labelling path)
    extended         the extended margin m_x: m_a continued to states without a Feasible Region

The names users need are exported by :mod:`margin_rl.stability`; the rest from their modules.
"""
