"""Damaged and odd ROS bags (issue 43): a corrupt bz2 or lz4 chunk, a
message whose values are absurd, image stamps that repeat, a bag whose own
message definitions differ from ROS's, and a short deterministic round of
the damage the fuzzer (tests/fuzz, target ``bag``) does at length: each is
one ValueError (or TypeError) naming the bag, the message or the frames,
and leaves no dataset; and what the damage cannot show (bits flipped
inside an image's pixels: a bag has no checksum) imports as it is."""

import os
import random
import shutil
import threading
import warnings

import numpy as np
import pytest
from bagrecords import chunks, damage_chunk, decompress
from bagtools import (
    PERIOD,
    STAMP0,
    compressed_image,
    good_images,
    jpeg_bytes,
    png_bytes,
    raw_image,
    stamp_text,
    write_camera_bag,
)
from clitools import assert_one_line_error, run, tiny_dataset
from sfanav import Dataset, write_dataset
from sfanav.data.images import damage
from sfanav.data.ros_messages import decode_compressed


def quiet(m):
    pass


def import_bag(bag, out, **kw):
    return Dataset.from_bag(bag, out, odom_topic="/odom", log=quiet, **kw)


# ---------------------------------------------------------------- compressed chunks

@pytest.mark.parametrize("compression, offsets, words", [
    ("bz2", range(100, 160), "Invalid data stream"),
    ("lz4", range(20, 30), "LZ4F_decompress failed"),  # a block's sequences (random pixels are literals, unchecked)
    ("lz4", [7], "LZ4F_getFrameInfo failed"),  # the frame's header
])
def test_a_corrupt_compressed_chunk_names_the_bag(tmp_path, capsys, compression, offsets, words):
    """Bytes inverted inside a bz2 or lz4 chunk's stream: "cannot read the
    bag NAME: ..." (was the library's bare message), in Python and as one
    line of sfanav import; nothing is written."""
    bag = write_camera_bag(tmp_path / "good.bag", [raw_image(i) for i in good_images(4)], compression=compression)
    data = bag.read_bytes()
    (chunk,) = chunks(data)
    assert chunk.fields[b"compression"] == compression.encode()
    bad = tmp_path / "bad.bag"
    bad.write_bytes(damage_chunk(data, chunk, list(offsets), before_compression=False))
    with pytest.raises(ValueError, match=rf"^cannot read the bag {bad}: {words}") as err:
        import_bag(bad, tmp_path / "ds")
    assert "\n" not in str(err.value)
    code, _, err = run(capsys, "import", bad, "--odom-topic", "/odom", "--out", tmp_path / "ds", "--no-progress")
    assert_one_line_error(code, err, f"cannot read the bag {bad}: {words}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bag", "good.bag"]
    assert len(import_bag(bag, tmp_path / "ok")) == 4  # the undamaged bag imports


@pytest.mark.parametrize("compression", ["bz2", "lz4", None])
def test_bit_flips_in_pixels_import_silently_but_not_in_png_data(tmp_path, compression):
    """What docs/security.md says: a bag carries no checksum, so a byte of a
    raw image's pixels inverted inside a chunk (compressed again, as a disk
    that flipped it before the recorder compressed it) imports as a wrong
    pixel; a PNG's own CRCs catch the same in a PNG image."""
    imgs = good_images(4)
    bag = write_camera_bag(tmp_path / "raw.bag", [raw_image(i) for i in imgs], compression=compression)
    data = bag.read_bytes()
    (chunk,) = chunks(data)
    plain = decompress(data[chunk.data_start : chunk.data_end], compression or "none")
    k = plain.find(imgs[2].tobytes()[:64])
    assert k > 0
    flipped = tmp_path / "flipped.bag"
    flipped.write_bytes(damage_chunk(data, chunk, [k + 10], before_compression=True))
    ds = import_bag(flipped, tmp_path / "ds")
    got = ds.load_images()
    assert (got[2] != imgs[2]).sum() == 1 and all((got[i] == imgs[i]).all() for i in (0, 1, 3))
    # a PNG image: its CRC-32 finds the flip
    png = png_bytes(imgs[2])
    assert damage(png) is None
    broken = bytearray(png)
    broken[len(png) // 2] ^= 0x10
    assert "fails its CRC-32" in damage(bytes(broken))
    images = [compressed_image(png_bytes(i), "png") for i in imgs[:2]] + [compressed_image(bytes(broken), "png")]
    bag = write_camera_bag(tmp_path / "png.bag", images + [compressed_image(png_bytes(imgs[3]), "png")])
    with pytest.raises(ValueError, match=rf"image 2 of /cam in {bag} \(t={stamp_text(STAMP0 + 2 * PERIOD)} s\): "
                                         r"cannot decode .*'IDAT' chunk .* fails its CRC-32"):
        import_bag(bag, tmp_path / "png")


def test_opencv_prints_nothing_of_its_own_for_a_garbage_image(capfd):
    """A JPEG with damaged coded data, a BMP header on random bytes: OpenCV
    used to print its codecs' warnings on stderr beside sfanav's one line."""
    rng = np.random.default_rng(1)
    jpeg = bytearray(jpeg_bytes(good_images(1)[0]))
    for k in range(300, len(jpeg) - 20, 11):
        jpeg[k] ^= 0x55
    for data in (bytes(jpeg), b"BM" + rng.bytes(300), b"\x89PNG\r\n\x1a\n" + rng.bytes(300)):
        with pytest.raises(ValueError, match="cannot decode the compressed image"):
            decode_compressed(np.frombuffer(data, np.uint8), "jpeg")
    out = capfd.readouterr()
    assert out.err == "" and out.out == ""
    # from several threads at once: the redirection is shared and undone when the last decode ends
    def decode_many():
        for _ in range(50):
            with pytest.raises(ValueError):
                decode_compressed(np.frombuffer(b"BM" + rng.bytes(300), np.uint8), "bmp")

    threads = [threading.Thread(target=decode_many) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    os.write(2, b"stderr is back\n")
    assert capfd.readouterr().err == "stderr is back\n"


# ---------------------------------------------------------------- absurd values, repeated stamps, odd types

@pytest.mark.parametrize("x", [1e308, -1e300, 2e9])
def test_an_absurd_odometry_value_is_one_line_naming_the_message(tmp_path, capsys, x):
    """Odometry at x = 1e308 (finite): one line naming the message, its
    stamp and the value; no RuntimeWarning, no "must be finite, got
    array([-inf, ...])" from the interpolation's overflow."""
    odom = [STAMP0 + k * PERIOD for k in range(-1, 5)]
    xs = [0.0, 0.1, 0.2, x, 0.4, 0.5]
    bag = write_camera_bag(tmp_path / "odd.bag", [raw_image(i) for i in good_images(4)], odom=odom, odom_x=xs)
    want = f"message 3 of /odom (odometry, t={stamp_text(odom[3])} s) has the position x={x!r}, y=0.0 m"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning (overflow) on the way
        with pytest.raises(ValueError, match="beyond 1e\\+09 m") as err:
            import_bag(bag, tmp_path / "ds")
    assert str(err.value).startswith(want)
    code, _, err = run(capsys, "import", bag, "--odom-topic", "/odom", "--out", tmp_path / "ds", "--no-progress")
    assert_one_line_error(code, err, want)
    assert not (tmp_path / "ds").exists()


def test_repeated_image_stamps_are_refused_at_import_naming_both_frames(tmp_path, capsys):
    """Two frames with one stamp: sfanav import refuses the bag, naming both
    images and their exact stamp (ns), instead of writing a dataset that
    sfanav train then refuses; stamps 1 ns apart import, and stay apart."""
    imgs = [raw_image(i) for i in good_images(4)]
    stamps = [STAMP0, STAMP0 + PERIOD, STAMP0 + PERIOD, STAMP0 + 3 * PERIOD]
    odom = [STAMP0 + k * PERIOD for k in range(-1, 5)]
    bag = write_camera_bag(tmp_path / "twice.bag", imgs, stamps=stamps, odom=odom)
    same = STAMP0 + PERIOD
    want = (f"image topic /cam: timestamps must increase strictly; images 1 and 2 have the same stamp "
            f"t={stamp_text(same)} s ({same} ns)")
    with pytest.raises(ValueError) as err:
        import_bag(bag, tmp_path / "ds")
    assert str(err.value).startswith(want), str(err.value)
    code, _, err = run(capsys, "import", bag, "--odom-topic", "/odom", "--out", tmp_path / "ds", "--no-progress")
    assert_one_line_error(code, err, want, "--time bag")
    assert not (tmp_path / "ds").exists()
    apart = [STAMP0, STAMP0 + PERIOD, STAMP0 + PERIOD + 1, STAMP0 + 3 * PERIOD]  # 1 ns apart: a float second can't
    assert apart[1] / 1e9 == apart[2] / 1e9
    ds = import_bag(write_camera_bag(tmp_path / "apart.bag", imgs, stamps=apart, odom=odom), tmp_path / "ok")
    assert ds.stamps_ns.tolist() == apart


def test_a_bag_whose_own_definition_lacks_a_field_is_named(tmp_path):
    """A ROS 2 bag carries its own message definitions (MCAP schemas, not
    checked against ROS's as ROS 1's md5sums are): a PoseStamped whose
    Quaternion has no z (found by the fuzzer: an AttributeError escaped) is
    a ValueError naming the message."""
    bag = write_camera_bag(tmp_path / "run", [raw_image(i) for i in good_images(3)], ros=2)
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    text = b"MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w"
    assert text in data
    odd = tmp_path / "odd.mcap"
    odd.write_bytes(data.replace(text, text.replace(b"float64 z", b"float64 q")))  # same length: offsets hold
    with pytest.raises(ValueError, match=rf"bag {odd}: message 0 of /odom is not a geometry_msgs/msg/PoseStamped as "
                                         r"ROS defines it .*no attribute 'z'"):
        import_bag(odd, tmp_path / "ds")


# ---------------------------------------------------------------- a round of the fuzzer's damage

def _damaged(data, rng):
    """One damaged copy of a bag, as tests/fuzz/mutations.py makes them."""
    kind = rng.random()
    found = chunks(data)
    if kind < 0.4 and found:
        chunk = rng.choice(found)
        before = rng.random() < 0.5
        return damage_chunk(data, chunk, [rng.randrange(2**31) for _ in range(rng.choice([1, 4, 16]))],
                            before_compression=before)
    if kind < 0.7:
        out = bytearray(data)
        for _ in range(rng.choice([1, 2, 16])):
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
        return bytes(out)
    return data[: rng.randrange(len(data))]


@pytest.mark.parametrize("name, kw", [("plain.bag", {}), ("bz2.bag", {"compression": "bz2"}),
                                      ("lz4.bag", {"compression": "lz4"}), ("run", {"ros": 2})])
def test_damaged_bags_fail_only_with_a_value_or_type_error_and_leave_nothing(tmp_path, name, kw):
    """40 damaged copies of a small bag (cut, bits flipped, compressed chunks
    damaged before or after compression): each imports or raises a
    ValueError or TypeError, never another exception, and a failure leaves
    no file behind."""
    src = write_camera_bag(tmp_path / name, [compressed_image(jpeg_bytes(i)) for i in good_images(3, h=4, w=6)],
                           **kw)
    path = next(src.glob("*.mcap")) if src.is_dir() else src
    data = path.read_bytes()
    work = tmp_path / "work"
    rng = random.Random(43)
    outcomes = {"imported": 0, "refused": 0}
    for i in range(40):
        work.mkdir()
        bag = work / f"damaged{path.suffix}"
        bag.write_bytes(_damaged(data, rng))
        try:
            import_bag(bag, work / "ds")
            outcomes["imported"] += 1
        except (ValueError, TypeError) as exc:
            assert "\n" not in str(exc), exc
            assert sorted(p.name for p in work.iterdir()) == [bag.name], (i, exc)
            outcomes["refused"] += 1
        shutil.rmtree(work)
    assert outcomes["refused"] > 10, outcomes


def test_train_names_repeated_stamps_exactly_and_trains_on_stamps_1_ns_apart(tmp_path, capsys):
    """A dataset from elsewhere whose run repeats a stamp: sfanav train
    (learning positions from odometry) names both frames and their exact
    stamps (were "1.733e+09 s" twice); stamps 1 ns apart, equal as float
    seconds, train."""
    ds, cfg = tiny_dataset(tmp_path)
    train = ds.select(run="train")
    ns = STAMP0 + np.round(train.timestamps * 1e9).astype(np.int64)
    for name, k, gap in (("twice", 5, 0), ("apart", 5, 1)):
        stamps = ns.copy()
        stamps[k + 1] = stamps[k] + gap
        write_dataset(tmp_path / name, train.images(), train.poses, odometry=train.odometry, stamps_ns=stamps,
                      runs="train")
        code, _, err = run(capsys, "train", "--dataset", tmp_path / name, "--config", cfg, "--supervision",
                             "odometry", "--readout", "quadratic", "--out", tmp_path / f"{name}.sfa", "--no-progress")
        if gap == 0:
            assert_one_line_error(code, err, f"frames {k} and {k + 1} have the same stamp "
                                             f"t={stamp_text(int(stamps[k]))} s ({int(stamps[k])} ns)",
                                  "learning positions from odometry needs the frames' times to increase strictly")
            assert not (tmp_path / f"{name}.sfa").exists()
        else:
            assert code == 0, err
            assert stamps[k] / 1e9 == stamps[k + 1] / 1e9


def test_a_record_with_an_empty_op_field_reads_as_unknown():
    """The fuzz harness's bag mutator met a record whose op field was empty (an IndexError in the harness, not in
    sfanav): such a record reads as op 0xff, like one without the field."""
    from bagrecords import Record

    assert Record(0, {b"op": b""}, 0, 0).op == 0xFF == Record(0, {}, 0, 0).op
    assert Record(0, {b"op": b"\x05"}, 0, 0).op == 5
