"""The default trim, ceil(3 f_s / cut-off) samples (:func:`ident.chain.default_rates`), does
not depend on how a period was stored: a cut-off that is a fraction of f_s (the 0.05 f_s floor)
and a period stored to 10 digits (the KUKA KR300 files' 0.0039999999 s for 4 ms) give
3 f_s / cut-off = 60.0000015, whose plain ceil was 61 where an exact period gives 60: every
decimated row moved by one sample (the KUKA command's cross-validation 11.4 -> 7.7 %)."""

from __future__ import annotations

import pytest

from ident.chain import TRIM_RTOL, default_rates


@pytest.mark.parametrize("period", [0.004, 0.0039999999, 0.0040000001])
def test_a_stored_period_rounding_does_not_move_the_trim(period):
    fs = 1.0 / period
    assert default_rates(fs, 12.5) == (20, 60, 60)
    assert default_rates(fs, 0.05 * fs)[1] == 60  # the cut-off floor as a fraction of f_s


def test_a_real_excess_still_rounds_up():
    # 3 f_s / cut-off = 60.01 and 60 * (1 + 10 TRIM_RTOL): a sample's share is a sample
    assert default_rates(1000.0, 3000.0 / 60.01)[1] == 61
    assert default_rates(1000.0, 3000.0 / (60 * (1 + 10 * TRIM_RTOL)))[1] == 61
    assert default_rates(1000.0, 50.0, trim=7)[1] == 7  # a given trim is kept
