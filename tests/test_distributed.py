"""Partitioned / distributed training: the partition pieces reproduce
Network.fit in this process, with loop closures, spatial pairs and
place-major orders too, and on a Dask LocalCluster (2 worker processes)
the fit equals the single-process fit, respects recording breaks, survives
a killed worker without double counting, and names a bad partition and
frame."""

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest
from clitools import SFANAV_ROOT
from sfanav import Network, Rotation
from sfanav.sfa.distributed import fit as distributed_fit
from sfanav.sfa.distributed import partitions_of

TINY = {
    "input": {"width": 60, "height": 8, "channels": 3},
    "network": {"precision": "double"},
    "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 5}],
}
ROT = Rotation(step=10)
N = 36


def _images(n=N, seed=0):
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
    return (out - out.min()) / (out.max() - out.min())


IMAGES = _images()


def _weights(net):
    """Every solved stage's (mean, projection, delta) of every node."""
    out = []
    for layer in net._net.node_states():
        for node in layer:
            for st in node["stages"]:
                sol = st["solution"]
                out += [np.asarray(sol["mean"]), np.asarray(sol["projection"]), np.asarray(sol["delta"])]
    return out


def _rel(a, b):
    """Largest relative difference; every third array is a mean, on the scale
    of the unit-variance signals (near 0 above the first layer): floor 1."""
    return max(float(np.max(np.abs(x - y)) / max(np.max(np.abs(x)), 1.0 if i % 3 == 0 else 1e-300))
               for i, (x, y) in enumerate(zip(a, b)))


def _n_pairs(net):
    return [st["stats"]["n_pairs"] for layer in net._net.node_states(with_statistics=True)
            for node in layer for st in node["stages"]]


def _n_samples(net):
    return [st["stats"]["n_samples"] for layer in net._net.node_states(with_statistics=True)
            for node in layer for st in node["stages"]]


def assert_same_fit(a, b, tol=1e-9, weight_tol=None, images=IMAGES):
    """Node weights and transform outputs agree to ``tol`` relative (the
    weights to ``weight_tol`` where the problem itself is ill-conditioned)."""
    wa, wb = _weights(a), _weights(b)
    assert len(wa) == len(wb) and wa
    assert _rel(wa, wb) < (weight_tol or tol), _rel(wa, wb)
    assert _n_samples(a) == _n_samples(b) and _n_pairs(a) == _n_pairs(b)
    ya, yb = a.transform(images), b.transform(images)
    assert np.max(np.abs(ya - yb)) / np.max(np.abs(ya)) < tol
    da, db = a.delta_values_, b.delta_values_
    np.testing.assert_allclose(da, db, rtol=tol, atol=tol * np.max(np.abs(da)))


def assert_same_features(a, b, tol=1e-9, images=IMAGES):
    """For fits whose top node has equal delta values (separate recordings
    give features constant within each recording, delta 0): the same delta
    values and the same feature space, the outputs one orthogonal basis
    change apart (within the equal-delta blocks), and the same counts."""
    da, db = a.delta_values_, b.delta_values_
    np.testing.assert_allclose(da, db, rtol=tol, atol=tol * np.max(np.abs(da)))
    ya, yb = a.transform(images), b.transform(images)
    r, *_ = np.linalg.lstsq(ya, yb, rcond=None)
    assert np.max(np.abs(ya @ r - yb)) / np.max(np.abs(yb)) < tol
    np.testing.assert_allclose(r @ r.T, np.eye(len(r)), atol=1e-6)
    assert _n_samples(a) == _n_samples(b) and _n_pairs(a) == _n_pairs(b)


@pytest.fixture(scope="module")
def reference():
    return Network(TINY).fit(IMAGES, ROT, cache=False, progress=False)


# ---------------------------------------------------------------- in process (no Dask)


@pytest.mark.parametrize("cuts", [[], [17], [5, 6, 30]])
def test_partitions_in_process_equal_fit(reference, cuts):
    parts = np.split(IMAGES, cuts)
    net = distributed_fit(Network(TINY), parts, ROT)
    assert net.is_fitted_ and net.n_partitions_ == len(parts)
    assert_same_fit(reference, net)
    assert _n_samples(net) == _n_samples(reference)


def test_one_array_npy_paths_and_uint8(tmp_path):
    u8 = (IMAGES * 255).astype(np.uint8)
    ref = Network(TINY).fit(u8, ROT, progress=False)
    assert_same_fit(ref, distributed_fit(Network(TINY), u8, ROT, n_partitions=3), images=u8)
    paths = []
    for i, part in enumerate(np.array_split(u8, 4)):
        paths.append(tmp_path / f"shard{i}.npy")
        np.save(paths[-1], part)
    assert_same_fit(ref, distributed_fit(Network(TINY), paths, ROT), images=u8)
    np.save(tmp_path / "all.npy", u8)
    assert_same_fit(ref, distributed_fit(Network(TINY), str(tmp_path / "all.npy"), ROT, n_partitions=2), images=u8)


@pytest.mark.parametrize("tw, fast", [(1.0, False), (3.0, True), (3.0, False)])
def test_transition_weight_and_naive_path(tw, fast):
    ref = Network(TINY).fit(IMAGES, ROT, transition_weight=tw, fast=fast, progress=False)
    net = distributed_fit(Network(TINY), np.split(IMAGES, [11, 25]), ROT, transition_weight=tw, fast=fast)
    # With tw != 1 the top node's expansion weights along near-null directions
    # of its covariance are ill-determined: even the single-process fast and
    # naive fits differ there by ~4e-7 relative; outputs and delta values
    # agree to 1e-9.
    assert_same_fit(ref, net, weight_tol=None if tw == 1.0 else 1e-5)


def test_breaks_wherever_they_fall():
    # (separate recordings make equal delta values: the fits are compared by
    # their feature spaces, delta values and counts)
    at_cut = distributed_fit(Network(TINY), np.split(IMAGES, [12, 20]), ROT, breaks=[20])
    inside = distributed_fit(Network(TINY), np.split(IMAGES, [12]), ROT, breaks=[20])
    whole = distributed_fit(Network(TINY), IMAGES, ROT, breaks=[20])
    assert_same_features(at_cut, inside)
    assert_same_features(at_cut, whole)
    # every partition its own recording = breaks at the partition starts
    assert_same_features(distributed_fit(Network(TINY), np.split(IMAGES, [20]), ROT, breaks="partitions"), whole)
    unbroken = distributed_fit(Network(TINY), np.split(IMAGES, [12, 20]), ROT)
    ya, yb = at_cut.transform(IMAGES), unbroken.transform(IMAGES)
    assert np.max(np.abs(np.abs(ya) - np.abs(yb))) > 1e-3
    # the break removes exactly the pairs between frame 19 and frame 20
    assert all(a < b for a, b in zip(_n_pairs(at_cut), _n_pairs(unbroken)))


def test_partition_links():
    parts = partitions_of([IMAGES[:5], IMAGES[5:9], IMAGES[9:]], breaks=[5, 7])
    assert [(p.start, p.n, p.continues, p.breaks) for p in parts] == [(0, 5, False, ()), (5, 4, False, (2,)),
                                                                      (9, 27, True, ())]
    with pytest.raises(ValueError, match="beyond"):
        partitions_of([IMAGES], breaks=[N])


def _dataset(path, images, runs):
    from sfanav.data.dataset import Dataset
    from sfanav.data.writer import DatasetWriter

    with DatasetWriter(path) as w:
        for i, (img, run) in enumerate(zip(images, runs)):
            w.add(img, frame=i, timestamp=float(i), pose=(0.1 * i, 0.0, 0.0), run=run)
    return Dataset(path)


def test_dataset_frames_with_runs_as_recordings(tmp_path):
    u8 = (IMAGES * 255).astype(np.uint8)
    ds = _dataset(tmp_path / "ds", u8, ["a"] * 20 + ["b"] * 16)
    parts = partitions_of(ds, n_partitions=3)
    assert [(p.start, p.n, p.continues, p.breaks) for p in parts] == [(0, 12, False, ()), (12, 12, True, (8,)),
                                                                      (24, 12, True, ())]
    net = distributed_fit(Network(TINY), ds, ROT, n_partitions=3)
    local = distributed_fit(Network(TINY), np.split(u8, [20]), ROT, breaks="partitions")
    assert_same_features(local, net, images=u8)


def test_bad_partition_is_named(tmp_path):
    bad = IMAGES.copy()
    bad[23, 2, 5, 1] = np.nan
    with pytest.raises(ValueError, match=r"partition 1 \(frames 12\.\.35 of the run\): frame 11 of the partition "
                                         r"\(frame 23 of the run\) contains NaN"):
        distributed_fit(Network(TINY), np.split(bad, [12]), ROT)
    with pytest.raises(ValueError, match="partition 2 .*8 px high|partition 2 .*channel"):
        distributed_fit(Network(TINY), [IMAGES[:5], IMAGES[5:9], IMAGES[9:, :, :, :1]], ROT)


def test_bad_options_are_refused():
    with pytest.raises(TypeError, match="list of arrays"):
        distributed_fit(Network(TINY), iter([IMAGES]), ROT)
    with pytest.raises(TypeError, match="dask.distributed.Client"):
        Network(TINY).fit(IMAGES, ROT, client=object(), pairs=([0], [1], [1.0]))
    with pytest.raises(ValueError, match="must index the 36 training images"):
        distributed_fit(Network(TINY), np.split(IMAGES, [12]), ROT, loop_closures=([0], [36], [0]))
    with pytest.raises(ValueError, match="more than one closure"):
        distributed_fit(Network(TINY), IMAGES, ROT, loop_closures=([0, 1], [5, 5], [0, 0]))
    with pytest.raises(ValueError, match="closure_weights needs loop_closures"):
        distributed_fit(Network(TINY), IMAGES, ROT, closure_weights=[1.0])
    with pytest.raises(ValueError, match="index the 36 training images"):
        distributed_fit(Network(TINY), IMAGES, ROT, pairs=([0], [36], [1.0]))
    with pytest.raises(ValueError, match="pair_layers must name layers 1..2"):
        distributed_fit(Network(TINY), IMAGES, ROT, pairs=([0], [3], [1.0]), pair_layers=[3])
    with pytest.raises(ValueError, match="pair_layers needs pairs"):
        distributed_fit(Network(TINY), IMAGES, ROT, pair_layers=[1])


# ---------------------------------------------------------------- loop closures, spatial pairs, place-major order

# closures whose current images sit at partition starts (12, 24) and ends (11, 23), with partners in other
# partitions, earlier and later
CLOSURES = (np.array([2, 5, 30, 0, 14, 3]), np.array([12, 11, 33, 24, 23, 20]), np.array([10, 0, 20, 30, 7, 59]))
RNG = np.random.default_rng(1)
# random pairs across the run, with repeats, a zero weight, an image with itself (skipped) and with itself rolled
PAIRS = (np.r_[RNG.integers(0, N, 40), 7, 9, 4], np.r_[RNG.integers(0, N, 40), 7, 9, 30],
         np.r_[RNG.uniform(0.1, 2, 40), 1.0, 1.0, 0.0])
SHIFTS = np.r_[RNG.integers(0, 60, 40), 20, 0, 5]
CUTS = [12, 24]


def assert_same_outputs(a, b, tol=1e-9, images=IMAGES):
    """Closures and pairs leave near-null directions of the top node's
    expansion ill-determined (single-process fast and naive fits differ
    there by 1e-7 to 1e-6 relative, as with transition_weight != 1):
    compare the outputs, delta values and counts to ``tol``, the weights
    to 1e-5."""
    assert_same_fit(a, b, tol=tol, weight_tol=1e-5, images=images)


@pytest.mark.parametrize("weights", [None, "half", "score"])
def test_loop_closures_in_process_equal_fit(weights):
    from types import SimpleNamespace

    lc = SimpleNamespace(past=CLOSURES[0], current=CLOSURES[1], shift=CLOSURES[2], score=np.linspace(0.2, 1.5, 6))
    w = {"half": np.full(6, 0.5), "score": "score"}.get(weights)
    ref = Network(TINY).fit(IMAGES, ROT, cache=False, progress=False, loop_closures=lc, closure_weights=w)
    assert ref.n_loop_closures_ == 6
    for parts in (IMAGES, np.split(IMAGES, CUTS), np.split(IMAGES, [5, 6, 30])):
        net = distributed_fit(Network(TINY), parts, ROT, loop_closures=lc, closure_weights=w)
        assert net.n_loop_closures_ == 6
        assert_same_outputs(ref, net)
    # the closures change the fit
    plain = distributed_fit(Network(TINY), np.split(IMAGES, CUTS), ROT)
    assert np.max(np.abs(np.abs(plain.transform(IMAGES)) - np.abs(ref.transform(IMAGES)))) > 1e-3


def test_partners_in_process_equal_fit():
    # the invariance training's explicit partners: corrupted copies of every image (here: noisy ones), half weight
    noisy = np.clip(IMAGES + np.random.default_rng(3).normal(0, 0.05, IMAGES.shape), 0, None).astype(IMAGES.dtype)
    partners = (np.arange(N), np.full(N, 0.5), noisy)
    ref = Network(TINY).fit(IMAGES, ROT, cache=False, progress=False, partners=partners)
    assert ref.n_partners_ == N and ref.n_loop_closures_ == 0
    for parts in (np.split(IMAGES, CUTS), np.split(IMAGES, [5, 6, 30])):
        net = distributed_fit(Network(TINY), parts, ROT, partners=partners)
        assert net.n_partners_ == N and net.n_loop_closures_ == 0
        assert_same_outputs(ref, net)
    with pytest.raises(ValueError, match="cannot be combined"):
        distributed_fit(Network(TINY), IMAGES, ROT, partners=partners, loop_closures=CLOSURES)
    with pytest.raises(ValueError, match="size and dtype"):
        distributed_fit(Network(TINY), IMAGES, ROT, partners=(np.arange(2), np.ones(2), noisy[:2, :, :10]))


@pytest.mark.parametrize("shifted, layers", [(False, None), (True, None), (True, [2])])
def test_spatial_pairs_in_process_equal_fit(shifted, layers):
    pairs = PAIRS + ((SHIFTS,) if shifted else ())
    ref = Network(TINY).fit(IMAGES, ROT, cache=False, progress=False, pairs=pairs, pair_layers=layers)
    # small pair tasks (at most 5 distinct images each): many tasks, images shared between them
    net = distributed_fit(Network(TINY), np.split(IMAGES, CUTS), ROT, pairs=pairs, pair_layers=layers,
                          pair_task_images=5)
    assert net.n_pairs_ == ref.n_pairs_ == len(PAIRS[0])
    assert_same_outputs(ref, net)
    assert_same_outputs(ref, distributed_fit(Network(TINY), IMAGES, ROT, pairs=pairs, pair_layers=layers))


def test_closures_and_pairs_together_on_the_naive_path_and_npy_shards(tmp_path):
    pairs = PAIRS + (SHIFTS,)
    kw = {"loop_closures": CLOSURES, "pairs": pairs, "fast": False}
    ref = Network(TINY).fit(IMAGES, ROT, cache=False, progress=False, **kw)
    paths = []
    for i, part in enumerate(np.split(IMAGES, CUTS)):
        paths.append(tmp_path / f"shard{i}.npy")
        np.save(paths[-1], part)
    assert_same_outputs(ref, distributed_fit(Network(TINY), paths, ROT, **kw))


def test_closures_and_pairs_read_from_a_dataset(tmp_path):
    u8 = (IMAGES * 255).astype(np.uint8)
    ds = _dataset(tmp_path / "ds", u8, ["a"] * N)
    kw = {"loop_closures": CLOSURES, "pairs": PAIRS + (SHIFTS,)}
    ref = Network(TINY).fit(u8, ROT, cache=False, progress=False, **kw)
    assert_same_outputs(ref, distributed_fit(Network(TINY), ds, ROT, n_partitions=3, pair_task_images=9, **kw),
                        images=u8)


def test_place_major_order_with_feedback():
    """Long-term training (thesis 6.2.2): two recordings of one route in
    place-major order, each image's partner the previous recording's image
    of the same place: an image order and loop closures like any other."""
    from sfanav.loopclosure import place_major_order

    rec = [IMAGES[:18], np.ascontiguousarray(IMAGES[18:][:, :, ::-1] * 0.7 + 0.2)]  # another "light"
    order = place_major_order([np.arange(18), np.arange(18)])
    X = np.concatenate(rec)[order]
    assert order[:4].tolist() == [0, 18, 1, 19]
    lc = (np.arange(0, 36, 2), np.arange(1, 36, 2), np.zeros(18, int))  # partner: the same place, other light
    ref = Network(TINY).fit(X, ROT, cache=False, progress=False, loop_closures=lc)
    # partitions cut between the two recordings' images of one place (a closure and its partner split)
    assert_same_outputs(ref, distributed_fit(Network(TINY), np.split(X, [7, 19, 29]), ROT, loop_closures=lc),
                        images=X)
    plain = Network(TINY).fit(X, ROT, cache=False, progress=False)
    assert_same_fit(plain, distributed_fit(Network(TINY), np.split(X, [7, 19, 29]), ROT), images=X)


def test_bad_partner_and_pair_images_are_named():
    from types import SimpleNamespace

    from sfanav.sfa.distributed_feedback import pair_statistics, pair_tasks

    bad = IMAGES.copy()
    bad[30, 2, 5, 1] = np.nan
    with pytest.raises(ValueError, match=r"loop-closure partner frame 30 of the run \(partition 2, partner of "
                                         r"frame 33\) contains NaN"):
        distributed_fit(Network(TINY), np.split(bad, CUTS), ROT, loop_closures=CLOSURES)
    parts = partitions_of(np.split(bad, CUTS))
    [task] = pair_tasks(([3, 30], [9, 31], [1.0, 1.0]), N, parts, 60, 8)
    assert task.ids == (3, 9, 30, 31) and task.owners == (0, 0, 2, 2)
    job = SimpleNamespace(layer=0, pass_=0, step=10, period=60, fast=True, transition_weight=1.0, batch_size=16)
    with pytest.raises(ValueError, match=r"pair task 0 \(2 pairs of frames 3..31 of the run\): frame 30 of the run "
                                         r"\(partition 2\) contains NaN"):
        pair_statistics(Network(TINY), job, task, bad[list(task.ids)])


# ---------------------------------------------------------------- Dask LocalCluster


@pytest.fixture(scope="module")
def client():
    pytest.importorskip("dask")
    distributed = pytest.importorskip("distributed")
    from dasktools import local_cluster

    with local_cluster(2) as cluster:
        c = distributed.Client(cluster)
        try:
            yield c
        finally:
            c.close()


def test_dask_fit_equals_single_process(client, reference, tmp_path):
    paths = []
    for i, part in enumerate(np.array_split(IMAGES, 5)):
        paths.append(str(tmp_path / f"shard{i}.npy"))
        np.save(paths[-1], part)
    net = Network(TINY).fit(paths, ROT, client=client, progress=False)
    assert net.n_partitions_ == 5
    assert_same_fit(reference, net)
    assert _n_samples(net) == _n_samples(reference)
    # one in-memory array, cut into one partition per worker
    assert_same_fit(reference, distributed_fit(Network(TINY), IMAGES, ROT, client=client))


def test_dask_array_and_breaks(client, reference):
    import dask.array as da

    arr = da.from_array(IMAGES, chunks=(7, 8, 60, 3))
    assert_same_fit(reference, distributed_fit(Network(TINY), arr, ROT, client=client))
    local = distributed_fit(Network(TINY), np.split(IMAGES, [10]), ROT, breaks=[10, 22])
    on_cluster = distributed_fit(Network(TINY), arr, ROT, client=client, breaks=[10, 22])
    assert_same_features(local, on_cluster)


def test_dask_dataset(client, tmp_path):
    u8 = (IMAGES * 255).astype(np.uint8)
    ds = _dataset(tmp_path / "ds", u8, ["a"] * 36)
    ref = Network(TINY).fit(u8, ROT, progress=False)
    assert_same_fit(ref, Network(TINY).fit(ds, ROT, client=client), images=u8)  # one partition per worker
    # the workers read the pair tasks' frames from the Dataset too
    kw = {"loop_closures": CLOSURES, "pairs": PAIRS + (SHIFTS,)}
    ref = Network(TINY).fit(u8, ROT, cache=False, progress=False, **kw)
    assert_same_outputs(ref, Network(TINY).fit(ds, ROT, client=client, **kw), images=u8)


def test_dask_closures_and_pairs(client, tmp_path):
    import dask.array as da

    kw = {"loop_closures": CLOSURES, "pairs": PAIRS + (SHIFTS,)}
    ref = Network(TINY).fit(IMAGES, ROT, cache=False, progress=False, **kw)
    paths = []
    for i, part in enumerate(np.split(IMAGES, CUTS)):
        paths.append(str(tmp_path / f"shard{i}.npy"))
        np.save(paths[-1], part)
    # .npy shards (the workers read the pairs' images), in-memory partitions (held on the cluster), a Dask array
    for images in (paths, np.split(IMAGES, CUTS), da.from_array(IMAGES, chunks=(10, 8, 60, 3))):
        net = Network(TINY).fit(images, ROT, client=client, progress=False, **kw)
        assert net.n_loop_closures_ == len(CLOSURES[0]) and net.n_pairs_ == len(PAIRS[0])
        assert_same_outputs(ref, net)


def _slow_block(path, lo, hi, log):
    """A Dask array block read slowly, logging every read (the kill test)."""
    with open(log, "a") as f:
        f.write(f"{lo} {os.getpid()}\n")
    time.sleep(0.4)
    return np.load(path)[lo:hi]


def test_killed_worker_is_retried_without_double_counting(client, reference, tmp_path):
    import dask
    import dask.array as da

    np.save(tmp_path / "all.npy", IMAGES)
    log = tmp_path / "reads.log"
    bounds = [(0, 9), (9, 18), (18, 27), (27, N)]
    arr = da.concatenate([
        da.from_delayed(dask.delayed(_slow_block)(str(tmp_path / "all.npy"), lo, hi, str(log)),
                        shape=(hi - lo, 8, 60, 3), dtype=np.float64) for lo, hi in bounds])
    pids = client.run(os.getpid)
    killed = []

    by_pid = {pid: addr for addr, pid in pids.items()}

    def killer():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            # a worker that logged a block read is reading it now (0.4 s): the log does not depend on how fast
            # the scheduler answers on a loaded machine
            lines = log.read_text().split("\n") if log.exists() else []
            for line in lines:
                parts = line.split()
                if len(parts) == 2 and int(parts[1]) in by_pid:
                    os.kill(int(parts[1]), signal.SIGKILL)
                    killed.append(by_pid[int(parts[1])])
                    return
            for addr, keys in client.processing().items():
                # a partition task, or a block read that one waits for
                if any("sfanav-partition" in str(k) or "_slow_block" in str(k) for k in keys) and addr in pids:
                    time.sleep(0.1)
                    os.kill(pids[addr], signal.SIGKILL)
                    killed.append(addr)
                    return
            time.sleep(0.05)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    net = distributed_fit(Network(TINY), arr, ROT, client=client)
    t.join(5)
    assert killed, "no worker was killed while a partition ran"
    assert_same_fit(reference, net)
    assert _n_samples(net) == _n_samples(reference)  # every image counted once
    client.wait_for_workers(2, timeout=60)


def test_lost_in_memory_partition_is_recomputed(client, reference):
    """In-memory partitions are held on the cluster for the whole fit; a
    worker killed after the first pass takes its copies along, and the
    later passes get them back from the task graph."""
    pids = client.run(os.getpid)
    killed = []

    def kill_a_holder(record):
        if killed:
            return
        for addr, keys in client.has_what().items():
            if any(str(k).startswith("sfanav-input-") for k in keys) and addr in pids:
                os.kill(pids[addr], signal.SIGKILL)
                killed.append(addr)
                return

    net = distributed_fit(Network(TINY), np.split(IMAGES, [10, 20, 30]), ROT, client=client, on_pass=kill_a_holder)
    assert killed
    assert_same_fit(reference, net)
    client.wait_for_workers(2, timeout=60)


def test_dask_bad_partition_is_named(client):
    bad = IMAGES.copy()
    bad[30, 0, 0, 0] = np.inf
    with pytest.raises(ValueError, match=r"partition 3 .*frame 3 of the partition \(frame 30 of the run\)"):
        distributed_fit(Network(TINY), np.split(bad, [9, 18, 27]), ROT, client=client)


def test_dask_default_malloc_setting_draws_a_warning(client):
    import warnings

    import distributed
    from dasktools import local_cluster

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the recommended setup: no warning
        distributed_fit(Network(TINY), IMAGES[:12], ROT, client=client)
    with (local_cluster(1, dask_malloc_default=True) as cluster, distributed.Client(cluster) as c,
          pytest.warns(UserWarning, match=r"MALLOC_TRIM_THRESHOLD_=65536 .*about 2x slower")):
        distributed_fit(Network(TINY), IMAGES[:12], ROT, client=c)


def test_dask_is_optional():
    """Importing sfanav and the distributed module does not import Dask."""
    import subprocess

    code = ("import sys, numpy as np, sfanav; from sfanav.sfa import distributed; "
            "assert 'dask' not in sys.modules and 'distributed' not in sys.modules")
    env = dict(os.environ, PYTHONPATH=SFANAV_ROOT)
    subprocess.run([sys.executable, "-c", code], check=True, env=env)
