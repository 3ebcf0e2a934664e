"""The probes' faster computations (issue 45 item 1) pinned to the straightforward ones they
replace, bit for bit, on small cases: the same expected images, so the same verdicts."""
import numpy as np

from spectral_bench.batch.verdict.probes import common


def test_lerp_is_the_fancy_indexed_interpolation_bit_for_bit():
    rng = np.random.default_rng(45)
    table = rng.normal(size=(1025, 3))
    x = rng.random((64, 33)) * (len(table) - 1)
    x[0, :3] = [0.0, len(table) - 1, len(table) - 1.5]  # both ends of the table
    i = np.minimum(x.astype(np.intp), len(table) - 2)
    f = x - i
    plain = table[i] + f[..., None] * (table[1:] - table[:-1])[i]
    fast = common.lerp(table, i, f)
    assert fast.shape == plain.shape == (64, 33, 3)
    assert np.array_equal(fast.view(np.int64), plain.view(np.int64))
