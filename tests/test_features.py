"""sfanav.features: the robustness vector, stability labels, the predictor
file, the features CLI and the 6.1 experiments' quick runs."""

import json
import subprocess
import sys

import numpy as np
import pytest
from clitools import SFANAV_ROOT
from sfanav.features import (
    DIM,
    Features,
    RobustnessPredictor,
    balanced,
    detect,
    match,
    robustness_vectors,
    select_ranked,
    stability_labels,
)

PY = SFANAV_ROOT


def _image(seed=0, h=40, w=160):
    return (np.random.default_rng(seed).random((h, w, 3)) * 255).astype(np.uint8)


def test_robustness_vector_is_77_normalised_histograms():
    v = robustness_vectors(_image(), np.array([[5.0, 3.0], [80.0, 20.0], [159.0, 39.0]]))
    assert v.shape == (3, DIM) == (3, 77)
    assert np.allclose(v[:, :59].sum(1), 1) and np.allclose(v[:, 59:].sum(1), 1) and (v >= 0).all()
    flat = np.full((40, 160, 3), (200, 30, 30), np.uint8)  # uniform red: one LBP code, one hue bin
    u = robustness_vectors(flat, [[50.0, 20.0]])
    assert np.isclose(u[0, :59].max(), 1) and np.isclose(u[0, 59:].max(), 1) and u[0, 59] == 1


def test_robustness_vector_refuses_bad_input():
    with pytest.raises(ValueError, match="RGB"):
        robustness_vectors(np.zeros((40, 160)), [[1.0, 1.0]])
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        robustness_vectors(_image(), [1.0, 2.0, 3.0])
    with pytest.raises(TypeError):
        robustness_vectors(_image(), [["a", "b"]])


def _feats(xy, bits):
    xy = np.asarray(xy, float)
    return Features(xy, np.arange(len(xy), 0, -1.0), np.ones(len(xy)), np.asarray(bits, np.uint8), True, 100)


def test_stability_labels_known_answer():
    d = np.eye(4, 32, dtype=np.uint8) * 255  # four far-apart binary descriptors
    a = _feats([[10, 10], [30, 10], [50, 10], [70, 10]], d)
    b = _feats([[11, 10], [30, 11], [90, 10], [70, 30]], d)  # 0, 1 in place; 2 and 3 moved
    c = _feats([[10, 11], [60, 10], [50, 10], [70, 10]], d)  # 0, 2, 3 in place; 1 moved
    la, lb, lc = stability_labels([a, b, c], threshold=5)
    assert la.tolist() == [1, -1, -1, -1]
    assert lb.tolist() == [1, -1, 0, 0] and lc.tolist() == [1, 0, -1, -1]
    idx = balanced(np.array([1, 0, 0, 0, -1, 1]), 0)
    assert sorted(np.array([1, 0, 0, 0, -1, 1])[idx].tolist()) == [0, 0, 1, 1]
    with pytest.raises(ValueError, match="two seasons"):
        stability_labels([a])


def test_detect_and_match_same_image():
    img = _image(1, 60, 300)
    f = detect(img, "fast-brief", 150)
    assert 0 < len(f) <= 150 and f.descriptors.shape[1] == 32 and np.all(np.diff(f.response) <= 0)
    pairs = match(f, f)
    assert len(pairs) > 0.9 * len(f) and np.all(pairs[:, 0] == pairs[:, 1])
    with pytest.raises(ValueError, match="unknown detector"):
        detect(img, "surf")


@pytest.fixture(scope="module")
def predictor():
    rng = np.random.default_rng(0)
    X = np.abs(np.vstack([rng.normal(0, 1, (30, DIM)), rng.normal(1.5, 1, (30, DIM))]))
    return RobustnessPredictor.fit(X, np.repeat([0, 1], 30), detector="fast-brief",
                                   grid={"C": [1.0, 10.0], "gamma": [0.01]}, cv=3), X


def test_predictor_matches_sklearn_and_round_trips(predictor, tmp_path):
    p, X = predictor
    from sklearn.svm import SVC

    svm = SVC(kernel="rbf", C=p.info["C"], gamma=p.gamma).fit((X - p.mean) / p.scale, np.repeat([0, 1], 30))
    assert np.allclose(p.decision_function(X), svm.decision_function((X - p.mean) / p.scale), atol=1e-8)
    path = p.save(tmp_path / "p.json")
    q = RobustnessPredictor.load(path)
    assert np.array_equal(q.decision_function(X), p.decision_function(X)) and q.detector == "fast-brief"
    sel = q.select(_image(2, 60, 300), 10)
    assert len(sel) == 10


def test_select_ranked_known_answers():
    s = np.array([0.1, -2.0, 1.5, 0.3, 5.0])  # scores of keypoints in response order
    # pool: the ceil(1.5 * 2) = 3 strongest; rank sums 0+1, 1+2, 2+0 -> keypoints 0 and 2 (tie: the stronger)
    assert select_ranked(s, 2, candidates=1.5, method="rank-sum").tolist() == [0, 2]
    assert select_ranked(s, 2, candidates=1.5, method="robust").tolist() == [2, 0]
    # the default: the most robust of the 4 k strongest (the whole list here): the fifth, weakest, gets in
    assert select_ranked(s, 2).tolist() == [4, 2]
    assert select_ranked(s, 2, candidates=3.0, method="robust").tolist() == [4, 2]
    assert select_ranked(s, 1).tolist() == [2]  # pool of 4: the fifth keypoint is out
    assert select_ranked(s, 10, method="rank-sum").tolist() == [0, 2, 4, 1, 3]  # rank sums 3, 5, 3, 5, 4
    assert select_ranked(s, 3, candidates=0.5, method="rank-sum").tolist() == [0, 2, 1]  # a pool below k counts as k
    assert select_ranked([], 3).tolist() == []
    for bad, match in (({"k": 0}, "k"), ({"candidates": 0.0}, "candidates"), ({"method": "best"}, "unknown selection"),
                       ({"scores": [[1.0]]}, "1-d"), ({"scores": [np.nan]}, "finite")):
        kw = {"scores": s, "k": 2, **bad}
        with pytest.raises(ValueError, match=match):
            select_ranked(kw.pop("scores"), kw.pop("k"), **kw)


def test_select_methods_keep_k_of_the_candidates(predictor):
    p, _ = predictor
    img = _image(2, 60, 300)
    pool = detect(img, "fast-brief", 40)
    scores = p.score_keypoints(img, pool)
    for method in ("rank-sum", "robust"):
        kept = p.select(img, 10, method=method)
        assert len(kept) == 10
        idx = select_ranked(scores, 10, method=method)
        np.testing.assert_array_equal(kept.xy, pool.xy[idx])
    assert np.array_equal(p.select(img, 10).xy, p.select(img, 10, method="robust", candidates=4.0).xy)
    with pytest.raises(ValueError, match="unknown selection method"):
        p.select(img, 10, method="best")


def test_predictor_file_rejects_corruption_and_wrong_version(predictor, tmp_path):
    p, _ = predictor
    path = p.save(tmp_path / "p.json")
    doc = json.loads(path.read_text())
    doc["predictor"]["intercept"] += 1.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="corrupted"):
        RobustnessPredictor.load(bad)
    doc = json.loads(path.read_text())
    doc["version"] = 99
    bad.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="version 99"):
        RobustnessPredictor.load(bad)
    bad.write_text("not json")
    with pytest.raises(ValueError, match="not JSON"):
        RobustnessPredictor.load(bad)
    with pytest.raises(FileNotFoundError):
        RobustnessPredictor.load(tmp_path / "missing.json")


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "sfanav", *args], capture_output=True, text=True, cwd=cwd,
                          env={"PYTHONPATH": PY, "PATH": "/usr/bin:/bin"})


def test_cli_errors_are_one_line(tmp_path, predictor):
    r = _cli("features", "select", "--predictor", str(tmp_path / "none.json"), "--dataset", str(tmp_path),
             "--out", str(tmp_path / "k.json"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "does not exist" in r.stderr
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    r = _cli("features", "select", "--predictor", str(bad), "--dataset", str(tmp_path), "--out",
             str(tmp_path / "k.json"))
    assert r.returncode == 2 and "not a robustness predictor" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = _cli("features", "train", "--dataset", str(tmp_path / "nope"), "--out", str(tmp_path / "p.json"))
    assert r.returncode == 2 and "dataset" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_experiments_quick_rows(tmp_path):
    from sfanav import experiments

    r = experiments.run("6.1.1", tmp_path, quick=True, progress=False)
    assert r.row("fast-brief: true matches, first frame") > 0
    assert r.row("best detector (most true matches over the year)") in ("fast-brief", "sift")
    r = experiments.run("6.1.2", tmp_path, quick=True, progress=False)
    assert np.isfinite(r.row("fast-brief: F1 gain % summer to spring"))
    # the thesis's rule and the predictors trained without the query season are reported beside the default
    assert np.isfinite(r.row("fast-brief: F1 gain % autumn to spring, selection 'thesis'"))
    assert np.isfinite(r.row("fast-brief: F1 gain % autumn to spring (autumn held out)"))
    assert 0.5 <= r.row("fast-brief: predictor CV accuracy (summer held out)") <= 1
    assert 0.5 <= r.row("fast-brief: predictor CV accuracy") <= 1
    assert any("thesis" in k for k in r.targets)


def test_cli_select_method(tmp_path, predictor):
    from sfanav.data.writer import DatasetWriter

    p, _ = predictor
    path = p.save(tmp_path / "p.json")
    with DatasetWriter(tmp_path / "ds", {"source": "test"}) as w:
        for k in range(2):
            w.add(_image(k, 60, 300), frame=k, timestamp=float(k), pose=(0.0, 0.0, 0.0), condition="spring")
    out = {}
    for method in ("rank-sum", "robust"):
        r = _cli("features", "select", "--predictor", str(path), "--dataset", str(tmp_path / "ds"), "--top-k", "10",
                 "--method", method, "--out", str(tmp_path / f"{method}.json"))
        assert r.returncode == 0, r.stderr
        out[method] = json.loads((tmp_path / f"{method}.json").read_text())
        assert out[method]["method"] == method and len(out[method]["images"][0]["keypoints"]) == 10
    img = _image(0, 60, 300)
    want = p.select(img, 10, method="robust")
    np.testing.assert_allclose([kp[:2] for kp in out["robust"]["images"][0]["keypoints"]], want.xy, atol=0.01)
    r = _cli("features", "select", "--predictor", str(path), "--dataset", str(tmp_path / "ds"), "--top-k", "10",
             "--method", "rank-sum", "--candidates", "1.5", "--out", str(tmp_path / "thesis-pool.json"))
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "thesis-pool.json").read_text())
    assert doc["candidates"] == 1.5
    want = p.select(img, 10, method="rank-sum", candidates=1.5)
    np.testing.assert_allclose([kp[:2] for kp in doc["images"][0]["keypoints"]], want.xy, atol=0.01)
    r = _cli("features", "select", "--predictor", str(path), "--dataset", str(tmp_path / "ds"), "--method", "best",
             "--out", str(tmp_path / "x.json"))
    assert r.returncode == 2 and "invalid choice" in r.stderr
    r = _cli("features", "select", "--predictor", str(path), "--dataset", str(tmp_path / "ds"), "--candidates", "0",
             "--out", str(tmp_path / "x.json"))
    assert r.returncode == 2 and "--candidates" in r.stderr and len(r.stderr.strip().splitlines()) <= 3
