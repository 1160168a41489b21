"""The Rerun live view (sfanav.odometry.live_view, localize --rerun): a
recording read back holds every image, estimate, fused position with its
covariance ellipse, the learned map and the ground truth."""

import csv

import numpy as np
import pytest

from sfanav.odometry.live_view import covariance_ellipse


def test_covariance_ellipse_is_the_sigma_contour():
    C = np.array([[0.5, 0.2], [0.2, 0.3]])
    P = covariance_ellipse([1.0, -2.0], C, sigma=2.0, n=40)
    d = P - [1.0, -2.0]
    np.testing.assert_allclose(np.einsum("ij,jk,ik->i", d, np.linalg.inv(C), d), 4.0, rtol=1e-12)
    np.testing.assert_array_equal(P[0], P[-1])
    assert np.allclose(covariance_ellipse([0, 0], np.zeros((2, 2))), 0)  # a certain position: a point
    with pytest.raises(ValueError, match="symmetric"):
        covariance_ellipse([0, 0], [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="positive semi-definite"):
        covariance_ellipse([0, 0], [[1.0, 0.0], [0.0, -1.0]])


def _entities(path):
    """{entity path: pyarrow table of its temporal rows}, plus the static rows under (path, "static")."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    parts = {}
    for ch in RrdReader(path).stream().to_chunks():
        key = (ch.entity_path, "static") if ch.is_static else ch.entity_path
        parts.setdefault(key, []).append(pa.Table.from_batches([ch.to_record_batch()]))
    return {k: pa.concat_tables(v, promote_options="permissive") for k, v in parts.items()}


def test_localize_writes_a_recording_that_reads_back(tmp_path, capsys):
    pytest.importorskip("rerun")
    from clitools import run, tiny_dataset

    ds, cfg = tiny_dataset(tmp_path)
    model = tmp_path / "tiny.sfa"
    assert run(capsys, "train", "--dataset", tmp_path / "data", "--config", cfg, "--out", model, "--no-progress")[0] == 0
    rrd, est = tmp_path / "run.rrd", tmp_path / "e.csv"
    code, out, err = run(capsys, "localize", model, tmp_path / "data", "--run", "test", "--odometry", "--out", est,
                         "--rerun", rrd, "--no-progress")
    assert code == 0, err
    assert "logged 40 estimates to Rerun" in err
    rows = list(csv.DictReader(open(est)))
    t = _entities(rrd)
    for e in ("/camera/image", "/world/estimate", "/world/fused", "/world/fused/ellipse", "/world/truth"):
        assert sorted(t[e].column("frame").to_pylist()) == list(range(40)), e
    order = np.argsort(t["/world/fused"].column("frame").to_pylist())
    fused = np.array([p[0] for p in t["/world/fused"].column("Points2D:positions").to_pylist()])[order]
    np.testing.assert_allclose(fused, [[float(r["fused_x"]), float(r["fused_y"])] for r in rows], atol=1e-4)
    order = np.argsort(t["/world/estimate"].column("frame").to_pylist())
    xy = np.array([p[0] for p in t["/world/estimate"].column("Points2D:positions").to_pylist()])[order]
    np.testing.assert_allclose(xy, [[float(r["x"]), float(r["y"])] for r in rows], atol=1e-4)
    test = ds.select(run="test")
    order = np.argsort(t["/world/truth"].column("frame").to_pylist())
    truth = np.array([p[0] for p in t["/world/truth"].column("Points2D:positions").to_pylist()])[order]
    np.testing.assert_allclose(truth, test.poses[:, :2], atol=1e-6)
    import sfanav

    m = np.array(t[("/world/map", "static")].column("Points2D:positions").to_pylist()[0])
    np.testing.assert_allclose(m, sfanav.load(model).training_positions_, atol=1e-6)
    strip = t["/world/fused/ellipse"].column("LineStrips2D:strips").to_pylist()[0][0]
    assert len(strip) == 33 and strip[0] == strip[-1]
    # an existing recording is not replaced without --overwrite; a bad target is one line
    code, _, err = run(capsys, "localize", model, tmp_path / "data", "--run", "test", "--out", tmp_path / "f.csv",
                       "--rerun", rrd, "--no-progress")
    assert code == 2 and "exists" in err
    code, _, err = run(capsys, "localize", model, tmp_path / "data", "--run", "test", "--out", tmp_path / "g.csv",
                       "--rerun", tmp_path / "x.txt", "--no-progress")
    assert code == 2 and "--rerun: a Rerun target is NAME.rrd" in err
    # without odometry: the estimates, no fused track
    code, _, err = run(capsys, "localize", model, tmp_path / "data", "--run", "test", "--out", tmp_path / "h.csv",
                       "--rerun", tmp_path / "plain.rrd", "--no-progress")
    assert code == 0, err
    t = _entities(tmp_path / "plain.rrd")
    assert sorted(t["/world/estimate"].column("frame").to_pylist()) == list(range(40)) and "/world/fused" not in t


def test_a_recording_carries_the_default_layout(tmp_path):
    """The camera view above the map view, the map view showing the past on
    both timelines, and the ellipse overridden to the present only."""
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from sfanav.odometry.live_view import RerunView

    view = RerunView(tmp_path / "r.rrd")
    view.log_map(np.zeros((3, 2)))
    view.close()
    reader = RrdReader(tmp_path / "r.rrd")
    (store,) = reader.blueprints()
    assert store.application_id == "sfanav"
    origins, names, overridden = set(), set(), []
    for ch in reader.stream(store=store).to_chunks():
        b = ch.to_record_batch()
        if "ViewBlueprint:space_origin" in b.schema.names:
            origins.update(str(v) for v in b.column("ViewBlueprint:space_origin").to_pylist()[0])
            names.update(str(v) for v in b.column("ViewBlueprint:display_name").to_pylist()[0])
        if ch.entity_path.endswith("overrides/world/fused/ellipse/visualizers"):
            overridden.append(b.column("VisibleTimeRanges:ranges").to_pylist()[0])
    assert {o.strip("/") for o in origins} == {"camera", "world"} and names == {"camera", "map and tracks"}
    assert len(overridden) == 1 and len(overridden[0]) == 2
