"""A position-error PDF with two modes has no one peak: both are named, the peak marked."""

import numpy as np

from rimcl.stats.peaks import pdf_modes
from rimcl.stats.summaries import position_summary
from rimcl.stats.tables import density_estimate


def _sample(share, rng, n=4000):
    """|ε| whose log10 is a mix of N(-3, 0.1) (``share``) and N(-2, 0.1)."""
    first = rng.random(n) < share
    logs = np.where(first, rng.normal(-3.0, 0.1, n), rng.normal(-2.0, 0.1, n))
    return 10.0**logs


def test_two_modes_of_comparable_height_are_both_named():
    rng = np.random.default_rng(1)
    modes = pdf_modes(*density_estimate(_sample(0.55, rng), log=True))
    assert len(modes) == 2
    np.testing.assert_allclose(np.log10(modes), [-3.0, -2.0], atol=0.05)  # the higher first
    # a small second population is no competing mode
    single = pdf_modes(*density_estimate(_sample(0.9, rng), log=True))
    assert len(single) == 1 and abs(np.log10(single[0]) + 3.0) < 0.05
    assert pdf_modes(np.array([1.0]), np.array([1.0])) == []


def test_the_position_summary_marks_an_ambiguous_peak():
    rng = np.random.default_rng(2)
    values = _sample(0.5, rng, 600)
    angle = rng.uniform(0, 2 * np.pi, values.size)
    vectors = (values * np.cos(angle), values * np.sin(angle))
    summary = position_summary(vectors, np.arange(values.size), 1.0, 1e-3)
    assert summary["position_error_peak_ambiguous"]
    assert len(summary["position_error_modes_over_L"]) == 2
    # the peak is one of the modes; its bootstrap interval spans both
    low, high = summary["position_error_peak_over_L_ci95"]
    assert low < 10**-2.5 < high
    single = _sample(1.0, rng, 600)
    plain = position_summary((single, np.zeros_like(single)), np.arange(single.size), 1.0, 1e-3)
    assert not plain["position_error_peak_ambiguous"]
