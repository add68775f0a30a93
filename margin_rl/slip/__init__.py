"""Actuated SLIP hopper, its learned failure-margin function and footstep planner (seed 001).

::

    aslip     the model's pieces: SlipParams, Status, the actuator profile, the stance vector field
    stance    the stance integrators: batched fixed-step RK4 with event location; solve_ivp per hop (reference)
    dynamics  one hop integrator: simulate_batch (flights in closed form, touchdown, stance, apex),
              simulate_hop (a batch of one), return_map; the model's description
    margin    the eq. (13) box, sampling, labelling and the k-d-tree failure margin (oriented distance)
    dataset   sharded, resumable state-action data set (python -m margin_rl.slip.dataset)
    models    the bundled P and M networks: their files, card and loading
    train     fit P and M (python -m margin_rl.slip.train)
    planner   the IPOPT footstep planner with margin constraints (paper Table I)

The layers imported from below are the base modules only: the networks are
:class:`margin_rl.network.DenseNetwork` (normalisation folded in; numpy, torch and CasADi forms) and their
files go through its helpers (``.npz`` without pickles, sha256 in the card, atomic writes). What stays
separate from the stability layer's learned margin, and why:

* the data set: uniformly sampled state-action pairs ``[y, xdot, alpha, delta_L]`` labelled by simulating
  one hop (status, next apex), with the margin computed afterwards over the whole set (k-d trees), not
  robot states labelled one by one with an analytic margin;
* the weights files: two networks (4-64-64-3 and 4-64-64-1, ReLU) under one ``card.json``, each with
  per-output normalisation vectors (``in_offset``, ``in_scale``, ``out_offset``, ``out_scale``), not one
  softsign network per robot with a lambda layout; the bundled files keep their format;
* training: a fixed number of Adam iterations on a weighted squared error (the return map's Q), without
  the stability trainer's epochs, early stopping, mirror tying or protocol evaluation.
"""
