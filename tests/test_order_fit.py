"""The order fit of the time-step study (chaingen.studies.order.fit_order) on synthetic data."""
from __future__ import annotations

import numpy as np
import pytest

from chaingen.studies.order import DEFAULT_DTS, fit_order


def test_fit_finds_the_power_law_between_floor_and_saturation():
    dts = np.array(DEFAULT_DTS)
    errors = 3.0 * dts ** 4
    errors[:2] = [2e-14, 7e-15]          # round-off floor at the small steps
    errors[-1] = 2e-4                    # saturated: no longer grows at dt = 0.2
    fit = fit_order(dts, errors, floor=1e-12)
    assert fit.order == pytest.approx(4.0, abs=1e-9)
    assert fit.coefficient == pytest.approx(3.0, rel=1e-9)
    assert fit.dts == (0.005, 0.01, 0.02, 0.05, 0.1)
    np.testing.assert_allclose(fit.predict(0.01), 3e-8, rtol=1e-9)


def test_fit_leaves_out_a_bending_end_and_failed_points():
    dts = np.array(DEFAULT_DTS)
    errors = list(0.5 * dts ** 2)
    errors[-2] = errors[-3] * 1.2        # slope ~0.3 against ~2 below: out of the regime
    errors[-1] = None                    # failed
    fit = fit_order(dts, errors)
    assert fit.order == pytest.approx(2.0, abs=1e-9)
    assert fit.dts == DEFAULT_DTS[:6]


def test_fit_prefers_the_small_dt_end_on_ties_and_needs_three_points():
    dts = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
    logs = np.log2(dts)
    # slope 2 over the first three, 3 between the third and fourth, 4 over the last three
    y = np.array([0, 2, 4, 7, 11, 15], dtype=float)
    fit = fit_order(dts, 2.0 ** y)
    assert fit.order == pytest.approx(2.0) and fit.dts == (1.0, 2.0, 4.0)
    assert np.allclose(np.diff(y) / np.diff(logs), [2, 2, 3, 4, 4])
    short = fit_order([0.1, 0.2, 0.4], [1e-3, 4e-3, None])
    assert short.order is None and short.dts == () and "only 2 of 3" in short.reason
    zigzag = fit_order([0.1, 0.2, 0.4, 0.8], [1e-3, 1e-2, 1e-2, 1e-1])
    assert zigzag.order is None and "slopes" in zigzag.reason


# --- the schemes' orders on three_link_mono (springs: the es energy error is not exact) ------

