"""Online updates of a trained network (sfanav.sfa.updates): with every
stage below the top layer's final stage frozen, updating with run A and
then run B equals training that stage on A + B (statistics and outputs to
1e-9), in any order and in one or several solves; runs that do not match
the model are refused and leave it as it was."""

import numpy as np
import pytest
from sfanav import Network, Rotation, _core
from sfanav.sfa.node import Statistics
from sfanav.sfa.updates import NetworkUpdater, UpdatePolicy, drop_statistics, statistics_bytes

TINY = {
    "input": {"width": 60, "height": 8, "channels": 3},
    "network": {"precision": "double"},
    "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 5}],
}
ROT = Rotation(step=10)


def _images(n, seed):
    """Smooth periodic panoramas with a little noise, float64 in [0, 1]."""
    rng = np.random.default_rng(seed)
    x = np.arange(60) * 2 * np.pi / 60
    y = np.arange(8)[:, None]
    out = np.empty((n, 8, 60, 3))
    walk = np.cumsum(rng.normal(0, 0.3, (n, 6)), axis=0)
    for i in range(n):
        p = walk[i]
        for c in range(3):
            out[i, :, :, c] = (np.sin(x + p[0] + 0.3 * y) + 0.5 * np.cos(2 * x + p[1] * (1 + c))
                               + 0.3 * np.sin(3 * x + p[2] * y) + 0.1 * rng.standard_normal((8, 60)))
    return np.clip((out + 2.5) / 5.0, 0.0, 1.0)


A, B, C = _images(24, 1), _images(18, 2), _images(10, 3)


@pytest.fixture(scope="module")
def net_a():
    return Network(TINY).fit(A, ROT, cache=False, progress=False)


def _blank(net):
    """``net`` with the top layer's final-stage statistics emptied: an
    update of it trains that stage on the given runs only."""
    from sfanav.sfa.modelfile import state_from_bytes

    state = state_from_bytes(net.to_bytes(include_statistics=True), "Network")
    for node in state["nodes"][-1]:
        st = node["stages"][-1]["stats"]
        node["stages"][-1]["stats"] = _core.Statistics(st["dim"]).get_state()
    return Network.from_state(state)


def _close(a, b, tol=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(1.0, float(np.abs(b).max()))
    assert float(np.abs(a - b).max()) <= tol * scale


def _same_stats(s, t):
    assert s.n_samples == t.n_samples and s.n_pairs == t.n_pairs
    _close(s.weight_sum, t.weight_sum)
    _close(s.pair_weight_sum, t.pair_weight_sum)
    _close(s.mean(), t.mean())
    _close(s.covariance(), t.covariance())
    _close(s.derivative_covariance(), t.derivative_covariance())


def _same_outputs(n1, n2, images):
    """Outputs equal up to each output's sign (SFA's ambiguity)."""
    y1, y2 = n1.transform(images), n2.transform(images)
    sign = np.sign(np.sum(y1 * y2, axis=0))
    _close(y1, y2 * sign)


def test_blank_update_with_a_reproduces_the_fit(net_a):
    up = NetworkUpdater(_blank(net_a)).partial_fit(A)
    ref = NetworkUpdater(net_a).top_statistics()
    for s, t in zip(up.top_statistics(), ref):
        _same_stats(s, t)
    _same_outputs(up.network_, net_a, C)


def test_a_then_b_equals_a_plus_b(net_a):
    upd = NetworkUpdater(net_a).partial_fit(B)
    b_only = NetworkUpdater(_blank(net_a)).partial_fit(B).top_statistics()
    merged = [s.copy().merge(b) for s, b in zip(NetworkUpdater(net_a).top_statistics(), b_only)]
    for s, t in zip(upd.top_statistics(), merged):
        _same_stats(s, t)
        assert s.n_samples > b_only[0].n_samples
    # one solve after A and B (policy every=N) and the other order give the same network
    both = NetworkUpdater(_blank(net_a), UpdatePolicy(every=len(A) + len(B)))
    both.partial_fit(A)
    assert both.n_solves_ == 0 and both.n_pending_ == len(A)
    both.partial_fit(B)
    assert both.n_solves_ == 1 and both.n_pending_ == 0
    reverse = NetworkUpdater(_blank(net_a)).partial_fit(B).partial_fit(A)
    for s, t in zip(both.top_statistics(), upd.top_statistics()):
        _same_stats(s, t)
    _same_outputs(both.network_, upd.network_, C)
    _same_outputs(reverse.network_, upd.network_, C)
    # the update changed the slow features, and the lower layer is untouched
    assert np.abs(np.abs(upd.network_.transform(C)) - np.abs(net_a.transform(C))).max() > 1e-6
    low = [n["stages"] for n in upd.network_._net.node_states()[0]]
    low_a = [n["stages"] for n in net_a._net.node_states()[0]]
    for x, y in zip(low, low_a):
        for sx, sy in zip(x, y):
            np.testing.assert_array_equal(sx["solution"]["projection"], sy["solution"]["projection"])


def test_updated_network_round_trips_and_keeps_updating(net_a, tmp_path):
    upd = NetworkUpdater(net_a).partial_fit(B).network_
    upd.save(tmp_path / "u.sfanav", include_statistics=True)
    again = NetworkUpdater(Network.from_bytes((tmp_path / "u.sfanav").read_bytes())).partial_fit(C)
    direct = NetworkUpdater(net_a).partial_fit(B).partial_fit(C)
    _same_outputs(again.network_, direct.network_, A[:5])
    assert net_a.transform(C).shape == (10, 5)  # the input network is not modified


def test_statistics_bytes_and_drop(net_a):
    n = statistics_bytes(net_a)
    small = drop_statistics(net_a)
    assert n > 0 and len(small.to_bytes()) + n == len(net_a.to_bytes(include_statistics=True))
    _same_outputs(small, net_a, C)
    with pytest.raises(ValueError, match="without its training statistics"):
        NetworkUpdater(small)


@pytest.mark.parametrize("bad, match", [
    (A[:, :, :50], "60x8"),              # panorama width
    (A[:, :6], "60x8"),                  # height
    (A[..., :1], "channel"),             # channels
    (A * 255.0, "scale"),                # 0..255 against 0..1
    (A[:0], "no images"),
    (np.where(np.arange(60)[:, None] == 3, np.nan, A[:4]), "NaN"),
])
def test_mismatched_run_is_refused_and_changes_nothing(net_a, bad, match):
    up = NetworkUpdater(net_a)
    before = [s.covariance() for s in up.top_statistics()]
    with pytest.raises(ValueError, match=match):
        up.partial_fit(bad)
    assert up.n_images_ == 0 and up.network_ is net_a
    for s, b in zip(up.top_statistics(), before):
        np.testing.assert_array_equal(s.covariance(), b)


def test_bad_arguments(net_a):
    with pytest.raises(ValueError, match="resolve"):
        UpdatePolicy(resolve="everything")
    with pytest.raises(ValueError):
        UpdatePolicy(every=0)
    with pytest.raises(TypeError, match="UpdatePolicy"):
        NetworkUpdater(net_a, "top")
    with pytest.raises(TypeError, match="Network"):
        NetworkUpdater(Statistics(3))
    with pytest.raises(Exception, match="not fitted"):
        NetworkUpdater(Network(TINY))


# ---------------------------------------------------------------- Network.partial_fit and sfanav update


def test_pairs_of_stage_inputs_add_exactly_their_derivative_moments(net_a):
    """add_pairs adds sum_i w_i d_i d_i^T (d the difference of the expanded
    stage inputs) to the updated stage's derivative moments and nothing to
    its samples; weight 0 changes nothing after a solve."""
    from sfanav import _core

    up = NetworkUpdater(net_a)
    (s0,) = up.top_statistics()
    rng = np.random.default_rng(4)
    k = 23
    A, B, w = rng.normal(size=(9, k)), rng.normal(size=(9, k)), rng.uniform(0, 2, 9)
    up.add_pairs(A, B, w)
    (s1,) = up.top_statistics()
    D = np.asarray(_core.expand(B, 2)) - np.asarray(_core.expand(A, 2))
    _close(s1.derivative_covariance() * s1.pair_weight_sum,
           s0.derivative_covariance() * s0.pair_weight_sum + (D * w[:, None]).T @ D, 1e-12)
    _close(s1.covariance(), s0.covariance(), 0)
    assert s1.n_samples == s0.n_samples and s1.n_pairs == s0.n_pairs + 9 and up.n_pairs_ == 9
    zero = NetworkUpdater(net_a).add_pairs(A, B, np.zeros(9)).solve()
    _same_outputs(zero, NetworkUpdater(net_a).solve(), _images(5, 9))


def test_network_partial_fit_matches_the_updater(net_a):
    net = Network.from_bytes(net_a.to_bytes(include_statistics=True))
    assert net.partial_fit(B) is net
    _same_outputs(net, NetworkUpdater(net_a).partial_fit(B).network_, C)


def _u8(x):
    return np.round(x * 255).astype(np.uint8)


def _dataset(path, images):
    from sfanav.data.dataset import write_dataset

    poses = np.c_[np.arange(len(images)) * 0.1, np.zeros(len(images)), np.zeros(len(images))]
    return write_dataset(path, list(images), poses)


def test_cli_update(tmp_path, capsys):
    from clitools import assert_one_line_error, run

    net = Network(TINY).fit(_u8(A), ROT, cache=False, progress=False)
    model = tmp_path / "net.sfanav"
    net.save(model, include_statistics=True)
    original = model.read_bytes()
    _dataset(tmp_path / "runb", _u8(B))
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "runb", "--out", tmp_path / "new.sfanav")
    assert code == 0, err
    assert "kept (" in out and "bytes" in out
    new = Network.from_bytes((tmp_path / "new.sfanav").read_bytes())
    _same_outputs(new, NetworkUpdater(net).partial_fit(_u8(B)).network_, _u8(C))
    assert model.read_bytes() == original
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "runb", "--out", tmp_path / "small.sfanav",
                         "--drop-statistics")
    assert code == 0 and "dropped" in out
    assert (tmp_path / "small.sfanav").stat().st_size < (tmp_path / "new.sfanav").stat().st_size
    # a run that does not match: gray images, another width; a model without statistics; the output exists
    _dataset(tmp_path / "gray", _u8(B[..., 0]))
    _dataset(tmp_path / "narrow", _u8(B[:, :, :50]))
    for bad, words in ((tmp_path / "gray", ("channel",)), (tmp_path / "narrow", ("50x8", "does not match"))):
        code, out, err = run(capsys, "update", model, "--dataset", bad, "--out", tmp_path / "bad.sfanav")
        assert_one_line_error(code, err, *words)
        assert not (tmp_path / "bad.sfanav").exists() and model.read_bytes() == original
    code, out, err = run(capsys, "update", tmp_path / "small.sfanav", "--dataset", tmp_path / "runb",
                         "--out", tmp_path / "bad.sfanav")
    assert_one_line_error(code, err, "without its training statistics")
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "runb", "--out", tmp_path / "new.sfanav")
    assert_one_line_error(code, err, "exists")
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "runb", "--out", model, "--overwrite")
    assert_one_line_error(code, err, "must differ")
    assert model.read_bytes() == original


def test_cli_update_reads_a_bag(tmp_path, capsys):
    """``--dataset`` may be a ROS bag: imported on the fly, the update equals
    the one from the images; without a pose topic one line, MODEL intact."""
    pytest.importorskip("rosbags")
    from bagtools import raw_image, write_camera_bag
    from clitools import assert_one_line_error, run

    net = Network(TINY).fit(_u8(A), ROT, cache=False, progress=False)
    model = tmp_path / "net.sfanav"
    net.save(model, include_statistics=True)
    original = model.read_bytes()
    bag = write_camera_bag(tmp_path / "runb.bag", [raw_image(i) for i in _u8(B)])
    code, out, err = run(capsys, "update", model, "--dataset", bag, "--odom-topic", "/odom",
                         "--out", tmp_path / "new.sfanav", "--no-progress")
    assert code == 0, err
    assert "importing" in err and f"updated with {len(B)} images" in out
    new = Network.from_bytes((tmp_path / "new.sfanav").read_bytes())
    _same_outputs(new, NetworkUpdater(net).partial_fit(_u8(B)).network_, _u8(C))
    code, out, err = run(capsys, "update", model, "--dataset", bag, "--out", tmp_path / "bad.sfanav")
    assert_one_line_error(code, err, "--odom-topic", "bag")
    code, out, err = run(capsys, "update", model, "--dataset", bag, "--odom-topic", "/odom", "--resolve", "all",
                         "--out", tmp_path / "bad.sfanav")
    assert_one_line_error(code, err, "is a network", "--keep-images")
    assert not (tmp_path / "bad.sfanav").exists() and model.read_bytes() == original
