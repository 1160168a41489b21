"""Estimates far outside the training positions are warned about and flagged.

The thesis's quadratic regression extrapolates without bound: features outside
their training range give positions far away (6.2.2's thesis configuration
with one training set once reported a mean error of 4.5e13 m). Pinned here:
the box distance, the readout's warning and count, the model state round trip,
and the experiment rows' flag (withheld figure, footnote in the CLI table).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sfanav.experiments import format_rows
from sfanav.experiments.flags import area_diagonal, flag_row
from sfanav.localization import QuadraticRegression
from sfanav.localization.extrapolation import (
    ExtrapolationWarning,
    count_extrapolated,
    distance_outside,
    training_bounds,
)


def test_distance_outside_box():
    b = [[0.0, 0.0], [1.0, 1.0]]
    d = distance_outside([[0.5, 0.5], [1.0, 1.0], [2.0, 0.5], [-3.0, 5.0], [np.nan, 0.0]], b)
    assert d.tolist() == [0.0, 0.0, 1.0, 5.0, np.inf]
    assert count_extrapolated([[1.6, 0.5], [1.8, 0.5]], b, margin=0.5) == 1  # diagonal sqrt 2: 0.707 m
    np.testing.assert_array_equal(training_bounds([[1, 5], [3, 2]]), [[1, 2], [3, 5]])
    with pytest.raises(ValueError, match="bounds"):
        distance_outside([[0, 0]], [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(ValueError, match="NaN or infinity"):
        training_bounds([[0.0, np.nan]])


def _fit():
    rng = np.random.default_rng(0)
    F = rng.uniform(-1, 1, size=(200, 2))
    xy = np.column_stack([F[:, 0] + F[:, 1] ** 2, F[:, 1]]) * 5.0  # quadratic in the features: fitted exactly
    return QuadraticRegression(n_outputs=2).fit(F, xy), F, xy


def test_inside_the_training_range_is_silent():
    reg, F, xy = _fit()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(reg.predict(F), xy, atol=1e-9)
    assert reg.n_extrapolated_ == 0
    np.testing.assert_allclose(reg.target_bounds_, [xy.min(0), xy.max(0)])


def test_far_outside_warns_once_and_counts():
    reg, F, _ = _fit()
    far = np.array([[30.0, 0.0], [0.0, 40.0], [0.1, 0.1]])  # the first two: hundreds of metres away
    with pytest.warns(ExtrapolationWarning, match="2 of 3 estimates"):
        reg.predict(far)
    assert reg.n_extrapolated_ == 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per fitted readout
        reg.predict(far)
    assert reg.n_extrapolated_ == 4
    reg.fit(F, F * 5)  # refit resets the count
    assert reg.n_extrapolated_ == 0


def test_state_round_trip_keeps_the_bounds():
    reg, F, _ = _fit()
    back = QuadraticRegression.from_state(reg.get_state())
    np.testing.assert_array_equal(back.target_bounds_, reg.target_bounds_)
    with pytest.warns(ExtrapolationWarning):
        back.predict([[30.0, 0.0]])
    old = {k: v for k, v in reg.get_state().items() if k != "target_bounds"}  # a model saved before the check
    assert not hasattr(QuadraticRegression.from_state(old), "target_bounds_")
    bad = dict(reg.get_state(), target_bounds=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="target_bounds"):
        QuadraticRegression.from_state(bad)


def test_flag_row_withholds_absurd_figures():
    row = {"metric": "MED (m), 1 training set [thesis config]", "thesis": None, "sfanav": 4.5e13}
    out = flag_row(row, extrapolated=120, estimates=400, diagonal=12.0)
    assert out["sfanav"] is None and out["withheld"] == 4.5e13
    assert "extrapolated (120 of 400" in out["flag"] and "not a figure" in out["flag"]
    assert row["sfanav"] == 4.5e13  # a copy
    mild = flag_row({"metric": "MED (m)", "sfanav": 1.7}, extrapolated=3, diagonal=12.0)
    assert mild["sfanav"] == 1.7 and "extrapolated (3 estimates" in mild["flag"]
    assert flag_row({"metric": "MED (m)", "sfanav": 0.3}, diagonal=12.0) == {"metric": "MED (m)", "sfanav": 0.3}
    assert flag_row({"metric": "x", "sfanav": float("nan")}, diagonal=1.0)["sfanav"] is None
    table = format_rows([out])
    assert "4.5e" not in table.split("flag:")[0] and table.splitlines()[-1].startswith("flag: MED (m), 1 training")
    assert area_diagonal([[0, 0], [3, 4], [1, 1]]) == 5.0


def test_cross_validation_inside_the_library_does_not_warn():
    """Held-out blocks at a run's edge lie outside their folds' box by
    construction: the library's own CV and resampling loops are quiet."""
    import warnings

    from sfanav.localization.extrapolation import ExtrapolationWarning, quiet_extrapolation
    from sfanav.localization.readout_selection import cross_val_predict

    rng = np.random.default_rng(0)
    xy = np.c_[np.linspace(0, 10, 60), np.zeros(60)]  # a straight run: the first and last blocks are outside
    F = np.c_[xy[:, 0], xy[:, 0] ** 3 / 10, rng.normal(size=(60, 6))]
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExtrapolationWarning)
        cross_val_predict({"kind": "quadratic", "n_outputs": 8, "ridge": 0.0}, F, xy, block=10)
        with quiet_extrapolation():
            warnings.warn("x", ExtrapolationWarning)
    with pytest.warns(ExtrapolationWarning):
        warnings.warn("shown again outside the context", ExtrapolationWarning)
