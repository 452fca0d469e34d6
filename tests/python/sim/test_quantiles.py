"""The harness's normal and beta quantiles (from scipy.special, which imports in a quarter of
scipy.stats's time) are scipy.stats's, bit for bit: a run's confidence intervals and exit
bounds do not depend on which module computes them."""
import numpy as np
import pytest
from scipy.stats import beta, norm

from stospline.harness.exit_stats import clopper_pearson_lower, clopper_pearson_upper
from stospline.harness.montecarlo import z_value


@pytest.mark.parametrize("confidence", [0.9, 0.95, 0.99, 0.999])
@pytest.mark.parametrize("comparisons", [1, 3, 40])
def test_z_value_is_scipy_stats(confidence, comparisons):
    q = 1 - (1 - confidence) / (2 * comparisons)
    assert z_value(confidence, comparisons) == float(norm.ppf(q))


def test_clopper_pearson_is_scipy_stats():
    rng = np.random.default_rng(5)
    for _ in range(300):
        n = int(rng.integers(1, 10**7))
        k = int(rng.integers(0, n + 1))
        c = float(rng.choice([0.9, 0.99, 0.9995]))
        up = 1.0 if k >= n else float(beta.ppf(c, k + 1, n - k))
        lo = 0.0 if k <= 0 else float(beta.ppf(1 - c, k, n - k + 1))
        assert clopper_pearson_upper(k, n, c) == up
        assert clopper_pearson_lower(k, n, c) == lo
