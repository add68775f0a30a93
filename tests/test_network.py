"""The base dense network: folding, its numpy, torch and CasADi forms against each other and against finite
differences, and the weights-file helpers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from margin_rl.network import (
    ACTIVATIONS,
    DenseNetwork,
    input_scaling,
    layer_arrays,
    read_arrays,
    read_layers,
    save_arrays,
    torch_forward,
    torch_sequential,
    verify_sha256,
    write_card,
)

WIDTHS = (5, 16, 12, 3)


def trained(activation: str, seed: int = 0, widths: tuple[int, ...] = WIDTHS) -> dict[str, object]:
    """Random layers and per-entry normalisation, as a training run would leave them."""
    rng = np.random.default_rng(seed)
    return {
        "weights": [rng.normal(0, 1 / np.sqrt(widths[k]), (widths[k + 1], widths[k])) for k in range(len(widths) - 1)],
        "biases": [rng.normal(0, 0.3, widths[k + 1]) for k in range(len(widths) - 1)],
        "activation": activation,
        "in_offset": rng.normal(size=widths[0]),
        "in_scale": rng.uniform(0.5, 2.0, widths[0]),
        "out_offset": rng.normal(size=widths[-1]),
        "out_scale": rng.uniform(0.1, 1.0, widths[-1]),
    }


def unfolded(p: dict[str, object], x: np.ndarray) -> np.ndarray:
    """The network as trained: normalise, layers, de-normalise (the reference for folding)."""
    h = (x - p["in_offset"]) / p["in_scale"]
    act = (lambda z: z / (1 + np.abs(z))) if p["activation"] == "softsign" else (lambda z: np.maximum(z, 0))
    for k, (w, b) in enumerate(zip(p["weights"], p["biases"], strict=True)):
        h = h @ w.T + b
        if k < len(p["weights"]) - 1:
            h = act(h)
    return p["out_offset"] + p["out_scale"] * h


def fold(p: dict[str, object]) -> DenseNetwork:
    return DenseNetwork.fold(p["weights"], p["biases"], p["activation"], **{k: p[k] for k in list(p)[3:]})


def inputs(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, WIDTHS[0]))


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_folding_keeps_the_function_and_single_inputs_match_batches(activation: str) -> None:
    p = trained(activation)
    net = fold(p)
    x = inputs(30)
    assert net.widths == WIDTHS and (net.in_dim, net.out_dim) == (5, 3)
    np.testing.assert_allclose(net(x), unfolded(p, x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([net(row) for row in x]), net(x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(net.value_float32(x), net(x), rtol=1e-5, atol=1e-5)
    assert net.value_float32(x).dtype == np.float32
    value, jacobian = net.value_and_grad(x)
    assert jacobian.shape == (30, 3, 5)
    np.testing.assert_allclose(value, net(x), rtol=0, atol=1e-12)
    v1, j1 = net.value_and_grad(x[4])
    np.testing.assert_allclose(v1, value[4], rtol=0, atol=1e-12)
    np.testing.assert_allclose(j1, jacobian[4], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(net.jacobian(x[4]), j1)


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_jacobian_matches_finite_differences(activation: str) -> None:
    net = fold(trained(activation, seed=2))
    x = inputs(6, seed=3)
    jacobian = net.jacobian(x)
    h = 1e-6
    for j in range(WIDTHS[0]):
        e = np.zeros(WIDTHS[0])
        e[j] = h
        fd = (net(x + e) - net(x - e)) / (2 * h)  # relu: random points are off the kinks
        np.testing.assert_allclose(fd, jacobian[:, :, j], rtol=0, atol=1e-7)


def test_single_output_batches_keep_their_jacobian_shape() -> None:
    net = fold(trained("softsign", widths=(4, 8, 1)))
    value, jacobian = net.value_and_grad(np.ones((3, 4)))
    assert value.shape == (3, 1) and jacobian.shape == (3, 1, 4)
    assert net.value_and_grad(np.ones(4))[1].shape == (1, 4)


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_torch_form_matches_numpy_and_finite_differences(activation: str) -> None:
    torch = pytest.importorskip("torch")
    net = fold(trained(activation, seed=4))
    x = inputs(10, seed=5)
    state = torch.random.get_rng_state()
    module = net.torch_module(torch.float64)
    assert torch.equal(state, torch.random.get_rng_state())  # copying weights in draws no random numbers
    out = module(torch.as_tensor(x))
    np.testing.assert_allclose(out.detach().numpy(), net(x), rtol=0, atol=1e-12)
    for row, expected in zip(x[:4], net.jacobian(x[:4]), strict=True):
        jac = torch.autograd.functional.jacobian(module, torch.as_tensor(row)).numpy()
        np.testing.assert_allclose(jac, expected, rtol=0, atol=1e-12)
        h = 1e-6
        with torch.no_grad():
            fd = np.column_stack(
                [(module(torch.as_tensor(row + h * e)) - module(torch.as_tensor(row - h * e))).numpy() / (2 * h)
                 for e in np.eye(WIDTHS[0])]
            )  # fmt: skip
        np.testing.assert_allclose(fd, jac, rtol=0, atol=1e-7)
    assert module[0].weight.dtype == torch.float64
    assert net.torch_module()[0].weight.dtype == torch.float32


def test_torch_training_pieces() -> None:
    """torch_sequential initialises like a stack of nn.Linear; torch_forward evaluates (weight, bias) pairs."""
    torch = pytest.importorskip("torch")
    from torch import nn

    torch.manual_seed(3)
    body = torch_sequential(WIDTHS, "relu")
    torch.manual_seed(3)
    reference = [nn.Linear(WIDTHS[k], WIDTHS[k + 1]) for k in range(len(WIDTHS) - 1)]
    linear = [m for m in body if isinstance(m, nn.Linear)]
    assert [type(m) for m in body] == [nn.Linear, nn.ReLU, nn.Linear, nn.ReLU, nn.Linear]
    for a, b in zip(linear, reference, strict=True):
        assert torch.equal(a.weight, b.weight) and torch.equal(a.bias, b.bias)
    x = torch.as_tensor(inputs(7), dtype=torch.float32)
    torch.testing.assert_close(torch_forward(x, [(m.weight, m.bias) for m in linear], "relu"), body(x))
    softsign = torch_sequential(WIDTHS, "softsign")
    assert isinstance(softsign[1], nn.Softsign)


def test_casadi_form_matches_numpy_and_finite_differences() -> None:
    ca = pytest.importorskip("casadi")
    for activation in ACTIVATIONS:
        net = fold(trained(activation, seed=6))
        x = inputs(4, seed=7)
        for sym in (ca.SX, ca.MX):
            z = sym.sym("z", WIDTHS[0], 4)
            f = ca.Function("f", [z], [net.casadi(z)])
            np.testing.assert_allclose(np.array(f(x.T)).T, net(x), rtol=0, atol=1e-12)
        z = ca.SX.sym("z", WIDTHS[0])
        expr = net.casadi(z)
        f = ca.Function("f", [z], [expr, ca.jacobian(expr, z)])
        for row, expected in zip(x, net.jacobian(x), strict=True):
            jac = np.array(f(row)[1])
            np.testing.assert_allclose(jac, expected, rtol=0, atol=1e-12)
            h = 1e-6
            fd = np.column_stack(
                [(np.array(f(row + h * e)[0]) - np.array(f(row - h * e)[0])).ravel() / (2 * h)
                 for e in np.eye(WIDTHS[0])]
            )  # fmt: skip
            np.testing.assert_allclose(fd, jac, rtol=0, atol=1e-7)


def test_bad_networks_and_inputs_are_refused() -> None:
    p = trained("softsign")
    with pytest.raises(ValueError, match="activation"):
        DenseNetwork(p["weights"], p["biases"], "tanh")
    with pytest.raises(ValueError, match="layer 1"):
        DenseNetwork([p["weights"][0], p["weights"][0], p["weights"][2]], p["biases"], "relu")
    with pytest.raises(ValueError, match="as many biases"):
        DenseNetwork(p["weights"], p["biases"][:2], "relu")
    with pytest.raises(ValueError, match="non-finite"):
        DenseNetwork(p["weights"], [p["biases"][0] * np.nan, *p["biases"][1:]], "relu")
    with pytest.raises(ValueError, match="nonzero"):
        DenseNetwork.fold(p["weights"], p["biases"], "relu", in_scale=0.0)
    net = fold(p)
    for bad in (np.zeros(4), np.zeros((2, 3, 5))):
        with pytest.raises(ValueError, match="shape"):
            net(bad)
    with pytest.raises(ValueError, match="batch"):
        net.value_float32(np.zeros(5))


def test_weights_file_helpers(tmp_path: Path) -> None:
    p = trained("relu")
    arrays = layer_arrays(p["weights"], p["biases"])
    assert list(arrays) == ["W0", "W1", "W2", "b0", "b1", "b2"] and arrays["W0"].dtype == np.float32
    digest = save_arrays(tmp_path / "net.npz", arrays)
    verify_sha256(tmp_path / "net.npz", digest)
    weights, biases = read_layers(read_arrays(tmp_path / "net.npz"), 3)
    np.testing.assert_array_equal(weights[1], np.float32(p["weights"][1]))
    assert biases[2].dtype == np.float64
    with pytest.raises(KeyError):
        read_layers(arrays, 4)
    with pytest.raises(RuntimeError, match="checksum mismatch"):
        verify_sha256(tmp_path / "net.npz", "0" * 64, RuntimeError)
    np.savez(tmp_path / "objects.npz", x=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="pickle"):
        read_arrays(tmp_path / "objects.npz")
    write_card(tmp_path / "card.json", {"b": 1, "a": [1, 2]})
    assert (tmp_path / "card.json").read_text() == '{\n  "b": 1,\n  "a": [\n    1,\n    2\n  ]\n}\n'


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_hessian_matches_finite_differences_of_the_gradient(activation: str) -> None:
    """Second-order backpropagation against central differences of the exact gradient; symmetric; a batch equals
    its rows; relu networks have no curvature (almost everywhere)."""
    p = trained(activation, widths=(5, 16, 12, 1))
    net = fold(p)
    x = inputs(6)
    hessians = net.hessian(x)
    assert hessians.shape == (6, 5, 5)
    np.testing.assert_allclose(hessians, np.swapaxes(hessians, 1, 2), rtol=0, atol=1e-12)
    step = 1e-6
    for i, row in enumerate(x):
        numeric = np.stack(
            [(net.jacobian(row + step * e)[0] - net.jacobian(row - step * e)[0]) / (2 * step) for e in np.eye(5)],
            axis=1,
        )
        np.testing.assert_allclose(hessians[i], numeric, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(net.hessian(row), hessians[i], rtol=0, atol=1e-12)
    if activation == "relu":
        assert np.all(hessians == 0.0)
    else:
        assert np.abs(hessians).max() > 1e-3


def test_hessian_needs_one_output() -> None:
    with pytest.raises(ValueError, match="one output"):
        fold(trained("softsign")).hessian(inputs(2))


def test_input_scaling_leaves_constant_columns_unscaled_and_folds_to_unit_variance() -> None:
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.normal(2.0, 3.0, 500), np.full(500, 1.0), rng.uniform(-1.0, 1.0, 500)])
    mean, std = input_scaling(x)
    np.testing.assert_allclose(mean, x.mean(axis=0))
    np.testing.assert_allclose(std, [x[:, 0].std(), 1.0, x[:, 2].std()])
    identity = DenseNetwork.fold([np.eye(3)], [np.zeros(3)], "softsign", in_offset=mean, in_scale=std)
    scaled = identity(x)
    np.testing.assert_allclose(scaled.std(axis=0), [1.0, 0.0, 1.0], atol=1e-12)
    assert input_scaling(x.astype(np.float32))[1].dtype == np.float32  # the inputs' dtype, as before
