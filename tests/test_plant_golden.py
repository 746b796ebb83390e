"""The single-joint simulator's numbers are those of the reference file (tests/plant_golden.py).

The reference was computed by the single-joint plant before it computed through the n-dof plant
(issue 24); every float column must agree to 1e-12 relative to the column's scale, and the
integer columns (encoder counts, per-mille targets, regimes) exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.plant_golden import GOLDEN, STRIDE, compute

#: Scenario prefix -> indices of the integer columns (exact match required).
INTEGER_COLUMNS = {"step": (4, 7, 8), "sim": (0, 1, 7), "payloads": (0, 1, 7), "inv": ()}


@pytest.fixture(scope="module")
def arrays():
    return compute()


def test_every_scenario_is_pinned(arrays):
    with np.load(GOLDEN) as g:
        assert sorted(g.files) == sorted(arrays)


@pytest.mark.parametrize("name", sorted(np.load(GOLDEN).files))
def test_numbers_unchanged(arrays, name):
    with np.load(GOLDEN) as g:
        ref = g[name]
    new = arrays[name][::STRIDE]
    assert new.shape == ref.shape
    ints = INTEGER_COLUMNS[name.split("_")[0]]
    for c in range(ref.shape[1]):
        if c in ints:
            np.testing.assert_array_equal(new[:, c], ref[:, c], err_msg=f"{name} column {c}")
        else:
            scale = max(1.0, float(np.max(np.abs(ref[:, c]))))
            np.testing.assert_allclose(new[:, c], ref[:, c], rtol=1e-12, atol=1e-12 * scale,
                                       err_msg=f"{name} column {c}")
