"""Hostile and absurd input: sizes beyond the machine, edited model files
with valid checksums, zip bombs and panics end in clear Python exceptions,
never an abort, a hang or a silent wrong result.

The allocation cases run in a subprocess under an address-space limit, so
that an allocation the core failed to refuse would show as a crash (or a
MemoryError) instead of passing on a machine with enough memory."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest
import sfanav
from conftest import correlated
from modeltools import edit_model, read_parts, set_array, strip_statistics, write_parts

LIMIT = 4_000_000_000  # bytes of address space for the subprocess cases


def run_limited(body: str, timeout: float = 120) -> str:
    """Runs ``body`` in a fresh interpreter under ``ulimit -v`` and returns
    its stdout; fails the test on a crash, a hang or a non-zero exit."""
    code = textwrap.dedent(f"""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, ({LIMIT}, {LIMIT}))
        import numpy as np, sfanav
        def expect(name, f):
            try:
                f()
            except ValueError as e:
                print(name, "ValueError", str(e).replace(chr(10), " "))
            else:
                print(name, "returned")
    """) + textwrap.dedent(body)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, check=False)
    assert r.returncode == 0, f"exit {r.returncode}\nstdout:\n{r.stdout}\nstderr:\n{r.stderr[-2000:]}"
    return r.stdout


def lines(out: str) -> dict[str, str]:
    return {ln.split(" ", 1)[0]: ln.split(" ", 1)[1] for ln in out.strip().splitlines()}


def test_allocations_beyond_the_machine_are_refused_before_allocating():
    out = lines(run_limited("""
        expect("sfa", lambda: sfanav.SFA(1, degree=8).fit(np.random.rand(20, 100)))
        expect("expand", lambda: sfanav.expand(np.zeros((10, 1000)), 4))
        expect("stats_huge", lambda: sfanav.Statistics(2**32 + 1))
        expect("stats", lambda: sfanav.Statistics(100000))
        expect("solve", lambda: sfanav.SFA(2, degree=3).fit(np.random.rand(50, 300)))
    """))
    for name in ("sfa", "expand", "stats_huge", "stats", "solve"):
        assert out[name].startswith("ValueError"), (name, out[name])
        assert "of memory; the limit is" in out[name], out[name]
    assert "degree-8 expansion of 100 features" in out["sfa"]
    assert "3.4 TB" in out["expand"]
    assert "160.0 GB" in out["stats"]


def test_networks_too_large_to_exist_are_refused_quickly():
    big = {"input": {"width": 100000, "height": 100000, "channels": 1}, "network": {"weight_sharing": False},
           "layers": [{"rf": [1, 1], "stride": [1, 1], "out": 1}, {"rf": "full", "out": 1}]}
    hang = {"input": {"width": 10**6, "height": 10**6, "channels": 1}, "network": {"max_expanded": 10**18},
            "layers": [{"rf": "full", "out": 8}]}
    out = lines(run_limited(f"""
        expect("nodes", lambda: sfanav.Network({big!r}))
        expect("hang", lambda: sfanav.Network({hang!r}))
    """, timeout=60))
    assert out["nodes"].startswith("ValueError") and "10000000001 nodes" in out["nodes"], out["nodes"]
    assert out["hang"].startswith("ValueError") and "of memory" in out["hang"], out["hang"]


def test_training_memory_is_checked_per_layer():
    # 400 positions, each with its own node of 2 x (48^2 + 300^2) f64 statistics
    cfg = {"input": {"width": 80, "height": 20, "channels": 1}, "network": {"weight_sharing": False},
           "layers": [{"rf": [4, 4], "stride": [4, 4], "out": 4}, {"rf": "full", "out": 2}]}
    net = sfanav.Network(cfg)
    sfanav.set_memory_limit(10**6)
    try:
        with pytest.raises(ValueError, match=r"training layer 1 \(100 node\(s\)"):
            net.fit(np.random.default_rng(0).random((3, 20, 80)), sfanav.Rotation(step=40), progress=False)
    finally:
        sfanav.set_memory_limit(None)


def test_memory_limit_can_be_set_and_restored():
    auto = sfanav.get_memory_limit()
    assert auto > 10**8
    sfanav.set_memory_limit(10**6)
    try:
        assert sfanav.get_memory_limit() == 10**6
        with pytest.raises(ValueError, match=r"statistics of 1000 features .* 16.0 MB of memory; the limit is 1.0 MB"):
            sfanav.Statistics(1000)
    finally:
        sfanav.set_memory_limit(None)
    assert sfanav.get_memory_limit() > 10**8
    sfanav.Statistics(1000)
    for bad, exc in ((-1, ValueError), (1.5, TypeError), ("1", TypeError)):
        with pytest.raises(exc):
            sfanav.set_memory_limit(bad)
    with pytest.raises(ValueError, match="n must be at least 0"):
        sfanav.set_num_threads(-1)


def test_expanded_dim_overflow_is_an_error():
    with pytest.raises(ValueError, match="too many terms"):
        sfanav.expanded_dim(2**64 - 1, 1)
    with pytest.raises(ValueError, match="too many terms"):
        sfanav.expanded_dim(2**63, 2)


@pytest.mark.parametrize("pooled", [False, True])
def test_a_panic_in_the_core_is_a_runtime_error(pooled):
    from sfanav import _core

    with pytest.raises(RuntimeError, match="internal error in sfanav's Rust core"):
        _core._test_panic(pooled)


# ------------------------------------------------------------------ model files
@pytest.fixture()
def sfa_file(tmp_path):
    p = tmp_path / "m.sfa"
    sfanav.SFA(2).fit(correlated(300, 3)).save(p)
    return p


@pytest.mark.parametrize("value", [2**20, 1000, 2**40, 2**63])
@pytest.mark.parametrize("statistics", [True, False])
def test_edited_dimensions_with_valid_checksums_are_refused(tmp_path, sfa_file, value, statistics):
    def edit(m, blobs):
        if not statistics:
            strip_statistics(m, blobs)
        node = m["state"]["node"]
        node["n_features"] = value
        node["stages"][0]["input_dim"] = value

    out = edit_model(sfa_file, tmp_path / "e.sfa", edit)
    with pytest.raises(ValueError, match=r"e\.sfa is not a valid sfanav SFA model: invalid model state: stage 0"):
        sfanav.load(out)


@pytest.mark.parametrize("field,value,message", [
    ("n_components", -3, "field 'n_components' must be a non-negative integer, got -3"),
    ("degree", 1.5, "field 'degree' must be a non-negative integer, got 1.5"),
    ("tol", "x", "field 'tol' must be a number, got 'x'"),
])
def test_edited_node_fields_name_the_field(tmp_path, sfa_file, field, value, message):
    def edit(m, blobs):
        m["state"]["node"][field] = value

    with pytest.raises(ValueError, match=message):
        sfanav.load(edit_model(sfa_file, tmp_path / "e.sfa", edit))


def test_statistics_inconsistent_with_their_arrays_are_refused(tmp_path, sfa_file):
    def edit(m, blobs):
        set_array(m, blobs, "node/stages/0/stats/sxx", np.zeros(4))

    with pytest.raises(ValueError, match="sxx has 4 values, expected 9"):
        sfanav.load(edit_model(sfa_file, tmp_path / "e.sfa", edit))


def test_non_finite_arrays_are_refused(tmp_path, sfa_file):
    def edit(m, blobs):
        set_array(m, blobs, "node/stages/0/solution/projection", np.full((6,), np.nan))

    with pytest.raises(ValueError, match="projection' holds NaN or infinity"):
        sfanav.load(edit_model(sfa_file, tmp_path / "e.sfa", edit))
    with pytest.raises(ValueError, match="NaN or infinity"):
        sfanav.sfa.save_model(tmp_path / "n.sfa", "SFA", {"a": np.array([1.0, np.inf])})


def test_array_header_must_match_its_data(tmp_path, sfa_file):
    def edit(m, blobs):
        name = "node/stages/0/solution/mean"
        header = blobs[name][: blobs[name].index(b"\n") + 1]
        big = header.replace(b"(3,)", b"(1000000000000,)")
        blobs[name] = big + blobs[name][len(header):]
        set_meta = m["arrays"][name]
        set_meta["shape"] = [10**12]
        import hashlib

        set_meta["sha256"] = hashlib.sha256(blobs[name]).hexdigest()

    with pytest.raises(ValueError, match="its header declares"):
        sfanav.load(edit_model(sfa_file, tmp_path / "e.sfa", edit))


def test_zip_bomb_is_refused_before_reading(tmp_path, sfa_file):
    m, blobs = read_parts(sfa_file)
    text = json.dumps(m).encode()
    padded = text[:-1] + b" " * 50_000_000 + text[-1:]  # valid JSON, same digest
    bomb = write_parts(tmp_path / "bomb.sfa", m, blobs, compression=zipfile.ZIP_DEFLATED, manifest_text=padded)
    assert bomb.stat().st_size < 200_000
    with pytest.raises(ValueError, match="is compressed"):
        sfanav.load(bomb)


def test_flipped_compression_method_is_a_value_error(tmp_path, sfa_file):
    data = bytearray(sfa_file.read_bytes())
    # the method field of the first local header and of the central directory
    data[8] = 99
    cd = data.rfind(b"PK\x01\x02")
    first_cd = data.find(b"PK\x01\x02")
    for at in {cd, first_cd}:
        data[at + 10] = 99
    p = tmp_path / "flip.sfa"
    p.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="not a valid sfanav model file"):
        sfanav.load(p)


def test_deeply_nested_manifest_is_refused(tmp_path, sfa_file):
    m, blobs = read_parts(sfa_file)
    deep: object = 0
    for _ in range(100):
        deep = [deep]
    m["state"]["extra"] = deep
    with pytest.raises(ValueError, match="nests more than 64 levels"):
        sfanav.load(write_parts(tmp_path / "deep.sfa", m, blobs))
    text = b'{"format": "sfanav-model", "x": ' + b"[" * 100_000 + b"]" * 100_000 + b"}"
    with zipfile.ZipFile(tmp_path / "deeper.sfa", "w") as zf:
        zf.writestr("manifest.json", text)
    with pytest.raises(ValueError, match="nests too deeply|nests more than"):
        sfanav.load(tmp_path / "deeper.sfa")


# -------------------------------------------------------------- networks, localizers
def tiny_network():
    cfg = {"input": {"width": 24, "height": 4, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [6, 4], "out": 4}, {"rf": "full", "out": 3}]}
    imgs = np.random.default_rng(1).random((30, 4, 24)).cumsum(0)
    return sfanav.Network(cfg).fit(imgs, sfanav.Rotation(step=6), progress=False), imgs


@pytest.fixture(scope="module")
def localizer_file(tmp_path_factory):
    net, imgs = tiny_network()
    xy = np.random.default_rng(2).random((len(imgs), 2))
    p = tmp_path_factory.mktemp("loc") / "loc.sfa"
    sfanav.Localizer(net, n_outputs=3, readout="quadratic").fit(imgs, xy).save(p)
    return p


@pytest.mark.parametrize("path,value,message", [
    (("network", "trained"), -1, "trained must be at least 0"),
    (("network", "trained"), 7, "layer count disagrees"),
    (("network", "step"), 0, "step must be at least 1"),
    (("rows",), 1, "AttributeError"),
    (("n_features_in",), 5, "the regression expects 5 features|does not fit its features"),
])
def test_edited_localizer_fields_are_refused(tmp_path, localizer_file, path, value, message):
    def edit(m, blobs):
        node = m["state"]
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value

    with pytest.raises(ValueError, match=message):
        sfanav.load(edit_model(localizer_file, tmp_path / "e.sfa", edit))


def test_network_node_config_is_cross_checked(tmp_path, localizer_file):
    def edit(m, blobs):
        m["state"]["network"]["nodes"][1][0]["degree"] = 3

    with pytest.raises(ValueError, match="layer 2 node disagrees with the spec"):
        sfanav.load(edit_model(localizer_file, tmp_path / "e.sfa", edit))


def test_readout_arrays_are_cross_checked(tmp_path, localizer_file):
    m, _ = read_parts(localizer_file)
    coef = next(n for n in m["arrays"] if n.startswith("readout/state/coef"))

    def wrong_shape(m, blobs):
        set_array(m, blobs, coef, np.zeros((9, 3)))

    with pytest.raises(ValueError, match="QuadraticRegression state|one finite"):
        sfanav.load(edit_model(localizer_file, tmp_path / "e.sfa", wrong_shape))


# ------------------------------------------------- regressions found by the fuzzers
def test_manifest_without_state_is_refused(tmp_path, sfa_file):
    def edit(m, blobs):
        del m["state"]

    with pytest.raises(ValueError, match="no 'arrays' table, 'kind' or 'state'"):
        sfanav.load(edit_model(sfa_file, tmp_path / "e.sfa", edit))


def test_a_model_file_cannot_name_a_config_file_to_read(tmp_path, localizer_file, monkeypatch):
    (tmp_path / "other.toml").write_text("[input]\nwidth = 1\n")
    monkeypatch.chdir(tmp_path)

    def edit(m, blobs):
        m["state"]["network"]["config"] = "other.toml"

    with pytest.raises(ValueError, match="the config must be a table, got str"):
        sfanav.load(edit_model(localizer_file, tmp_path / "e.sfa", edit))


@pytest.mark.parametrize("edit,message", [
    (lambda c: c["layers"][0].update(degree=2**31 - 1), "degree must be 1, 2 or 3"),
    (lambda c: c.update(name=True), "name must be a string"),
    (lambda c: c.setdefault("network", {}).update(tol=[1]), "tol must be a number"),
])
def test_config_values_found_by_the_fuzzer(edit, message):
    cfg = {"input": {"width": 24, "height": 4, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [6, 4], "out": 4}, {"rf": "full", "out": 3}]}
    edit(cfg)
    with pytest.raises(ValueError, match=message):
        sfanav.Network(cfg)


# --------------------------------------------------------------- clear messages
def test_finite_input_that_overflows_is_named():
    X = correlated(200, 3) * 1e120
    with pytest.raises(ValueError, match="finite but too large: its degree-3 expansion overflows"):
        sfanav.SFA(2, degree=3).fit(X)
    m = sfanav.SFA(2, degree=2).fit(correlated(200, 3))
    with pytest.raises(ValueError, match="finite but too large"):
        m.transform(X * 1e100)
    with pytest.raises(ValueError, match="statistics overflowed"):
        sfanav.SFA(2).fit(X * 1e180)


def test_zero_weights_batch_size_and_channel_messages():
    with pytest.raises(ValueError, match="weights of all 500 training samples are 0"):
        sfanav.Statistics(3).add_samples(np.random.default_rng(0).random((500, 3)), np.zeros(500)).covariance()
    net, imgs = tiny_network()
    with pytest.raises(ValueError, match="batch_size must be at least 1, got 0"):
        sfanav.Network(net.config).fit(imgs, sfanav.Rotation(step=6), progress=False, batch_size=0)
    rgb = {**net.config, "input": {**net.config["input"], "channels": 3}}
    rgb_net = sfanav.Network(rgb).fit(np.repeat(imgs[..., None], 3, axis=3), sfanav.Rotation(step=6),
                                      progress=False)
    with pytest.raises(ValueError, match="with 1 channel.*takes 4 px high images with 3 channel"):
        rgb_net.transform(imgs)  # a batch of gray images, not one RGB image of 30 x 4 x 24


def test_another_pixel_scale_than_in_training_warns(tmp_path):
    rng = np.random.default_rng(4)
    imgs = (rng.random((30, 4, 24)).cumsum(0) % 1 * 255).astype(np.uint8)
    cfg = {"input": {"width": 24, "height": 4, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [6, 4], "out": 4}, {"rf": "full", "out": 3}]}
    net = sfanav.Network(cfg).fit(imgs, sfanav.Rotation(step=6), progress=False)
    assert net.input_scale_ > 200
    with pytest.warns(UserWarning, match="trained on values up to"):
        net.transform(imgs / 255.0)
    net.save(tmp_path / "n.sfa")
    back = sfanav.load(tmp_path / "n.sfa")
    assert back.input_scale_ == net.input_scale_
    with pytest.warns(UserWarning, match="trained on values up to"):
        back.transform(imgs.astype(np.float32) / 255)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back.transform(imgs)  # the training scale: no warning


def test_negative_and_fractional_config_values_name_the_key():
    cfg = {"input": {"width": 24, "height": 4, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [6, 4], "out": -4}, {"rf": "full", "out": 3}]}
    with pytest.raises(ValueError, match="layer 1: out"):
        sfanav.Network(cfg)
    cfg["layers"][0]["out"] = 4
    cfg["input"]["width"] = 24.5
    with pytest.raises(ValueError, match="width"):
        sfanav.Network(cfg)
