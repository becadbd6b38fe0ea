"""The compiled bootstrap row statistics equal numpy's row reductions bit for bit."""

import numpy as np
import pytest

from railval.core.bootstrap import resample_mean_std


def _numpy_rows(d, idx):
    sample = d[idx]
    n = sample.shape[1]
    means = np.add.reduce(sample, axis=1) / n
    x = sample - means[:, None]
    var = np.add.reduce(np.multiply(x, x, out=x), axis=1) / max(n - 1, 0)
    return means, np.sqrt(var)


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("n", [*range(2, 20), 31, 34, 68, 127, 128, 129, 136, 255, 256,
                               257, 300, 1000, 1031])
def test_rows_equal_numpy(n):
    rng = np.random.default_rng(n)
    for d in (rng.standard_normal(n),
              rng.standard_normal(n) * 10.0 ** rng.integers(-6, 9, n),
              1e6 + rng.standard_normal(n),
              -np.zeros(n),
              np.where(rng.random(n) < 0.5, -0.0, 1e-300)):
        idx = rng.integers(0, n, size=(60, n))
        got, want = resample_mean_std(d, idx), _numpy_rows(d, idx)
        assert np.array_equal(_bits(got[0]), _bits(want[0]))
        assert np.array_equal(_bits(got[1]), _bits(want[1]))
        narrow = resample_mean_std(d, idx.astype(np.uint16))  # the kept indices' form
        assert np.array_equal(_bits(narrow[0]), _bits(got[0]))
        assert np.array_equal(_bits(narrow[1]), _bits(got[1]))
        assert np.array_equal(_bits(got[0]), _bits(d[idx].mean(axis=1)))
        assert np.array_equal(_bits(got[1]), _bits(d[idx].std(axis=1, ddof=1)))
