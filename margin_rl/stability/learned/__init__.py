"""The learned margin of seed 000 §IV: a network that maps lambda to the margin 10^3 times faster than the LPs.

::

    features     cheap physics features of lambda (ICP, load-shifted support polygon, friction), exact Jacobians
    mlp_weights  the network as data: architectures, weights, their files and model cards (bundled in weights/);
                 MarginWeights.network() folds them into the base margin_rl.network.DenseNetwork, the one
                 implementation of the numpy, torch and CasADi forms
    model        LearnedMargin.load(robot): value, gradient, torch module, ONNX (lambda layout, physics features)
    margin_mlp   torch modules: MarginMLP to train (plain or mirror-tied), MarginModule on trained weights
    dataset      states labelled with m_a and m_x in resumable shards (python -m margin_rl.stability.learned.dataset)
    training     fit a network on a dataset (python -m margin_rl.stability.learned.training)
    evaluation   the paper's protocol (§V-A) beside the held-out metrics
    figures      Fig. 1/2-style figures of a network against the analytic margin
"""

from margin_rl.stability.learned.model import LearnedMargin

__all__ = ["LearnedMargin"]
