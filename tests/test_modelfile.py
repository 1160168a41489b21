"""Model files: versioned, checksummed, pickle-free, bit-exact round trips."""

import json
import zipfile

import numpy as np
import pytest

import sfanav
from conftest import correlated


@pytest.mark.parametrize("params", [dict(), dict(degree=2), dict(degree=2, reduce_to=3)])
def test_round_trip_is_bit_exact(tmp_path, params):
    X = correlated(1000, 5, seed=1)
    m = sfanav.SFA(2, **params).fit(X)
    m.save(tmp_path / "m.sfa")
    back = sfanav.load(tmp_path / "m.sfa")
    assert isinstance(back, sfanav.SFA)
    assert back.get_params() == m.get_params()
    np.testing.assert_array_equal(back.delta_values_, m.delta_values_)
    np.testing.assert_array_equal(back.transform(X), m.transform(X))


def test_training_continues_after_load(tmp_path):
    X = correlated(2000, 4, seed=2)
    a = sfanav.SFA(2).partial_fit(X[:1000])
    a.save(tmp_path / "a.sfa")
    b = sfanav.load(tmp_path / "a.sfa").partial_fit(X[1000:])
    ref = sfanav.SFA(2).fit(X)
    np.testing.assert_allclose(b.delta_values_, ref.delta_values_, rtol=1e-10)


def test_without_statistics_cannot_train_further(tmp_path):
    X = correlated(500, 3, seed=3)
    sfanav.SFA(2).fit(X).save(tmp_path / "s.sfa", include_statistics=False)
    m = sfanav.load(tmp_path / "s.sfa")
    np.testing.assert_array_equal(m.transform(X), sfanav.SFA(2).fit(X).transform(X))
    with pytest.raises(ValueError, match="without training statistics"):
        m.partial_fit(X)


def test_unfitted_round_trip(tmp_path):
    sfanav.SFA(3, degree=2).save(tmp_path / "u.sfa")
    m = sfanav.load(tmp_path / "u.sfa")
    assert m.get_params()["degree"] == 2
    with pytest.raises(sfanav.NotFittedError):
        m.transform(np.ones((2, 2)))


def test_file_is_a_documented_zip_without_pickle(tmp_path):
    sfanav.SFA(2).fit(correlated(300, 3)).save(tmp_path / "m.sfa")
    with zipfile.ZipFile(tmp_path / "m.sfa") as zf:
        names = zf.namelist()
        manifest = json.loads(zf.read("manifest.json"))
        assert all(n == "manifest.json" or n.endswith(".npy") for n in names)
        for n in names:
            if n.endswith(".npy"):
                np.load(zf.open(n), allow_pickle=False)  # would raise on object arrays
    assert manifest["format"] == "sfanav-model" and manifest["version"] == 1
    assert manifest["kind"] == "SFA"


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="no model file"):
        sfanav.load("/nonexistent/model.sfa")


def test_truncated_file(tmp_path):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).fit(correlated(300, 3)).save(p)
    data = p.read_bytes()
    for cut in (10, len(data) // 2, len(data) - 5):
        q = tmp_path / f"cut{cut}.sfa"
        q.write_bytes(data[:cut])
        with pytest.raises(ValueError, match="not a valid sfanav model file"):
            sfanav.load(q)


def _rewrite(src, dst, edit_manifest=None, edit_array=None):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for n in zin.namelist():
            blob = zin.read(n)
            if n == "manifest.json" and edit_manifest:
                m = json.loads(blob)
                edit_manifest(m)
                blob = json.dumps(m).encode()
            if n.endswith(".npy") and edit_array and edit_array[0] in n:
                blob = blob[:-8] + np.float64(edit_array[1]).tobytes()
            zout.writestr(n, blob)


def test_altered_array_is_detected(tmp_path):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).fit(correlated(300, 3)).save(p)
    _rewrite(p, tmp_path / "x.sfa", edit_array=("projection", 123.0))
    with pytest.raises(ValueError, match="altered"):
        sfanav.load(tmp_path / "x.sfa")


def test_altered_manifest_is_detected(tmp_path):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).fit(correlated(300, 3)).save(p)

    def edit(m):
        m["state"]["params"]["tol"] = 0.5

    _rewrite(p, tmp_path / "x.sfa", edit_manifest=edit)
    with pytest.raises(ValueError, match="manifest was altered"):
        sfanav.load(tmp_path / "x.sfa")


def test_newer_version_is_refused(tmp_path):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).save(p)

    def edit(m):
        m["version"] = 99

    _rewrite(p, tmp_path / "x.sfa", edit_manifest=edit)
    with pytest.raises(ValueError, match="version 99.*upgrade sfanav"):
        sfanav.load(tmp_path / "x.sfa")


@pytest.mark.parametrize("version, message", [(0, "version 0 does not exist"), (-3, "version -3 does not exist"),
                                              (True, "an integer"), ("2", "an integer"), (None, "an integer")])
def test_impossible_versions_are_refused(tmp_path, version, message):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).save(p)

    def edit(m):
        m["version"] = version

    _rewrite(p, tmp_path / "x.sfa", edit_manifest=edit)
    with pytest.raises(ValueError, match=message):
        sfanav.load(tmp_path / "x.sfa")


def test_not_a_model_file(tmp_path):
    p = tmp_path / "x.sfa"
    p.write_text("hello")
    with pytest.raises(ValueError, match="not a valid sfanav model file"):
        sfanav.load(p)
    with pytest.raises(IsADirectoryError):
        sfanav.load(tmp_path)
