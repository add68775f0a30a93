"""benchmarks/studies/field_control_weight.py: K₀ of the control's acceleration penalty, on hand-solvable inputs."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.studies.field_control_weight import SCAN, control_weight


def test_k0_is_the_margin_terms_mean_magnitude_over_the_mean_squared_acceleration() -> None:
    terms = np.array([0.002, -0.004, 0.0, 0.006])  # mean |term| 0.003
    accelerations = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])  # |a|^2 25 and 1: mean 13
    result = control_weight(terms, accelerations)
    assert result.margin_term_abs == pytest.approx(0.003) and result.acceleration_sq == pytest.approx(13.0)
    assert result.k0 == pytest.approx(0.003 / 13.0)
    assert result.scan == pytest.approx(tuple(result.k0 * m for m in SCAN)) and SCAN == (1.0, 10.0, 100.0)
    assert result.steps == {"margin": 4, "baseline": 2}


@pytest.mark.parametrize(
    ("terms", "accelerations", "message"),
    [
        (np.array([]), np.ones((2, 3)), "need margin terms"),
        (np.ones(3), np.ones((2, 2)), "need margin terms"),
        (np.array([np.nan]), np.ones((2, 3)), "finite"),
        (np.ones(3), np.zeros((4, 3)), "all zero"),
    ],
)
def test_bad_inputs_are_refused(terms: np.ndarray, accelerations: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        control_weight(terms, accelerations)
