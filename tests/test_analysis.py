"""eta values, delta values, plots and the Markdown report."""

import numpy as np
import pytest

import sfanav
from sfanav.sfa import delta_values, eta_values, orientation_angles, plot_eta
from sfanav.localization import plot_error_vs_n, plot_firing_maps, plot_trajectory, write_report
from sfanav.localization import error_vs_n, evaluate_test_run

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def signals():
    """P = 50 positions x K = 12 orientations; f codes position, g orientation."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 3, (50, 2))
    phi = np.deg2rad(orientation_angles(12))
    f = np.cos(np.pi * xy[:, 0] / 3)  # position only
    g = np.sin(phi)  # orientation only
    return xy, f, g


def test_eta_of_pure_position_and_pure_orientation_signals(signals):
    xy, f, g = signals
    P, K = len(f), len(g)
    pos = np.repeat(f[:, None], K, axis=1)  # s(p, phi) = f(p)
    ori = np.repeat(g[None, :], P, axis=0)  # s(p, phi) = g(phi)
    mixed = pos + 0.5 * ori  # additive: each variance is exactly its own part's
    s = np.stack([pos, ori, mixed], axis=2)  # (P, K, 3)
    eta_p, eta_phi = eta_values(s)
    np.testing.assert_allclose(eta_p, [f.var(), 0.0, f.var()], atol=1e-12)
    np.testing.assert_allclose(eta_phi, [0.0, g.var(), 0.25 * g.var()], atol=1e-12)
    # a unit-variance position code: the thesis's ideal eta_p = 1, eta_phi = 0
    unit = (pos - pos.mean()) / pos.std()
    e = eta_values(unit[:, :, None])
    assert e.eta_p[0] == pytest.approx(1.0) and e.eta_phi[0] == pytest.approx(0.0, abs=1e-12)
    # normalised: fractions of each output's total variance
    n_p, n_phi = eta_values(s * 7.0, normalize=True)
    np.testing.assert_allclose(n_p[[0, 1]], [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(n_p[2] + n_phi[2], 1.0)  # additive and independent on a full grid
    np.testing.assert_allclose(eta_values(s * 7.0).eta_p, 49 * eta_p, atol=1e-12)  # raw: not normalised


def test_eta_is_mean_of_variances_not_variance_of_means():
    # s(p, phi) = p * phi: the variance over positions depends on phi
    p = np.arange(4.0)[:, None]
    phi = np.array([0.0, 1.0, 2.0])[None, :]
    s = (p * phi)[:, :, None]
    eta_p, eta_phi = eta_values(s)
    assert eta_p[0] == pytest.approx(np.mean([np.var(p * k) for k in (0, 1, 2)]))
    assert eta_phi[0] == pytest.approx(np.mean([np.var(q * phi) for q in range(4)]))


def test_eta_errors():
    with pytest.raises(ValueError, match=r"rotations=True"):
        eta_values(np.zeros((5, 3)))
    bad = np.zeros((5, 3, 2))
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        eta_values(bad)
    with pytest.raises(ValueError, match="constant"):
        eta_values(np.zeros((5, 3, 2)), normalize=True)


def test_delta_values_match_sfa():
    t = np.linspace(0, 2 * np.pi, 3000)
    X = np.c_[np.sin(t) + np.cos(11 * t) ** 2, np.cos(11 * t)]
    sfa = sfanav.SFA(2, degree=2).fit(X)
    np.testing.assert_allclose(delta_values(sfa.transform(X)), sfa.delta_values_, rtol=1e-6)
    np.testing.assert_allclose(sfanav.sfa.beta_values(sfa.delta_values_), sfa.beta_values_)
    with pytest.raises(ValueError, match="at least 2 rows"):
        delta_values(np.zeros((1, 3)))


def test_orientation_angles():
    np.testing.assert_allclose(orientation_angles(4), [0, 90, 180, 270])
    np.testing.assert_allclose(orientation_angles(3, step=5, width=12), [0, 150, 300])


def _is_png(path):
    with open(path, "rb") as fh:
        return fh.read(8) == PNG_MAGIC


def test_plots_write_pngs(tmp_path, signals):
    xy, f, g = signals
    s = np.stack([np.repeat(f[:, None], 12, 1), np.repeat(g[None], 50, 0), np.outer(f, g)], axis=2)
    out = plot_firing_maps(s, xy, tmp_path / "maps.png", which=(0, 1, 2), title="maps")
    assert out == tmp_path / "maps.png" and _is_png(out)
    assert _is_png(plot_firing_maps(s[:, 0], xy, tmp_path / "maps1.png", which=(0,)))
    assert _is_png(plot_firing_maps(s, xy, tmp_path / "sub" / "binned.png", which=(1,), bins=5))
    pred = xy + 0.1
    assert _is_png(plot_trajectory(xy, pred, tmp_path / "traj.png", error_lines=True, title="t"))
    pred[3] = np.nan  # random-split predictions may hold NaN rows
    assert _is_png(plot_trajectory(xy, pred, tmp_path / "traj2.png", connect=False))
    assert _is_png(plot_error_vs_n([2, 3, 4], [0.3, 0.2, 0.1], [0.4, 0.3, 0.35], tmp_path / "e.png", best_n=3))
    assert _is_png(plot_eta([1.0, 0.9], [0.0, 0.1], tmp_path / "eta.png"))
    F = np.random.default_rng(0).normal(size=(80, 6))
    curve = error_vs_n(F[:40], F[:40, :2] ** 2, F[40:], F[40:, :2] ** 2, ns=range(2, 7))
    assert _is_png(curve.plot(tmp_path / "curve.png"))


def test_plot_errors(tmp_path, signals):
    xy, f, _ = signals
    s = np.repeat(f[:, None, None], 4, axis=1)
    with pytest.raises(ValueError, match="PNG"):
        plot_firing_maps(s, xy, tmp_path / "maps.jpg", which=(0,))
    with pytest.raises(ValueError, match=r"which must list output indices in 0..0"):
        plot_firing_maps(s, xy, tmp_path / "maps.png", which=(0, 1))
    with pytest.raises(ValueError, match="outputs has 50 rows but xy has 49"):
        plot_firing_maps(s, xy[:-1], tmp_path / "maps.png", which=(0,))
    with pytest.raises(ValueError, match=r"angles must have shape \(4,\)"):
        plot_firing_maps(s, xy, tmp_path / "maps.png", which=(0,), angles=[0, 90])
    with pytest.raises(ValueError, match="shape of xy_true"):
        plot_trajectory(xy, xy[:-1], tmp_path / "t.png")
    with pytest.raises(ValueError, match="one value per n"):
        plot_error_vs_n([2, 3], None, [0.1], tmp_path / "e.png")


def test_report_embeds_figures_and_metrics(tmp_path):
    rng = np.random.default_rng(0)
    F = rng.normal(size=(60, 4))
    xy = F[:, :2] + 0.01 * rng.normal(size=(60, 2))
    res = evaluate_test_run(F[:40], xy[:40], F[40:], xy[40:], n_outputs=2)
    fig = plot_trajectory(xy[40:], res.predictions, tmp_path / "figs" / "traj.png")
    report = write_report(
        tmp_path / "out" / "report.md",
        title="Garden run",
        text="Trained on run 1.",
        metrics={"SFA": res, "perfect memory": {"med": 0.5, "bytes_per_place": 14000, "note": "a|b"}},
        figures=[("test trajectory", fig)],
    )
    text = report.read_text()
    assert text.startswith("# Garden run") and "Trained on run 1." in text
    assert "| | protocol | n | med |" in text and "| SFA | test-run | 20 |" in text
    assert "| perfect memory |" in text and "14000" in text and "a\\|b" in text
    assert "![test trajectory](../figs/traj.png)" in text
    with pytest.raises(TypeError, match="metrics row"):
        write_report(tmp_path / "r.md", metrics={"x": 3.0})
