"""The dataset format: round trip, real recordings with pose interpolation,
insect-navigation image databases, error cases."""

import csv

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sfanav
from sfanav import Dataset, DatasetWriter, write_dataset
from sfanav.data import read_image, write_image


def images(n, h=6, w=10, rgb=True, seed=0):
    rng = np.random.default_rng(seed)
    shape = (n, h, w, 3) if rgb else (n, h, w)
    return rng.integers(0, 256, shape, dtype=np.uint8)


def test_round_trip(tmp_path):
    n = 7
    imgs = images(n)
    rng = np.random.default_rng(1)
    poses = rng.normal(size=(n, 3))
    odo = poses + 0.01
    ds = write_dataset(tmp_path / "d", iter(imgs), poses, timestamps=np.arange(n) * 0.5, odometry=odo,
                       cameras=["left", "right"] * 3 + ["left"], conditions="sunny", runs="train",
                       frames=[0, 0, 1, 1, 2, 2, 3], extra={"segment": [0, 0, 1, 1, -1, -1, 2]},
                       metadata={"note": "test"})
    assert len(ds) == n and isinstance(ds, sfanav.Dataset)
    np.testing.assert_array_equal(ds.poses, poses)  # repr() keeps every bit
    np.testing.assert_array_equal(ds.odometry, odo)
    np.testing.assert_array_equal(ds.timestamps, np.arange(n) * 0.5)
    assert ds.has_odometry
    assert list(ds.cameras) == ["left", "right"] * 3 + ["left"]
    assert set(ds.conditions) == {"sunny"} and set(ds.runs) == {"train"}
    np.testing.assert_array_equal(ds.column("segment"), [0, 0, 1, 1, -1, -1, 2])
    assert ds.metadata["note"] == "test" and ds.metadata["units"]["heading"] == "rad"
    for i, img in enumerate(ds.images()):
        np.testing.assert_array_equal(img, imgs[i])
    batches = list(ds.images(batch_size=3))
    assert [b.shape for b in batches] == [(3, 6, 10, 3), (3, 6, 10, 3), (1, 6, 10, 3)]
    np.testing.assert_array_equal(np.concatenate(batches), imgs)
    g = ds.image(2, gray=True, size=(5, 3))
    assert g.shape == (3, 5) and g.dtype == np.uint8
    left = ds.select(camera="left")
    assert len(left) == 4 and list(left.frames) == [0, 1, 2, 3]
    np.testing.assert_array_equal(left.load_images(), imgs[[0, 2, 4, 6]])
    assert len(Dataset(tmp_path / "d", camera="right")) == 3
    assert len(ds.subset([6, 0])) == 2 and ds.subset([6, 0]).frames[0] == 3
    assert "7 images" in repr(ds)


def test_images_are_read_lazily(tmp_path):
    ds = write_dataset(tmp_path / "d", images(3), np.zeros((3, 3)))
    (tmp_path / "d" / "images" / "000002_center.png").unlink()
    it = ds.images()
    next(it), next(it)  # the first two still read
    with pytest.raises(FileNotFoundError, match="000002_center.png"):
        next(it)


def test_gray_images_and_png_round_trip(tmp_path):
    img = images(1, rgb=False)[0]
    write_image(tmp_path / "g.png", img)
    np.testing.assert_array_equal(read_image(tmp_path / "g.png"), img)
    rgb = images(1)[0]
    write_image(tmp_path / "c.png", rgb)
    np.testing.assert_array_equal(read_image(tmp_path / "c.png"), rgb)
    with pytest.raises(TypeError, match="uint8"):
        write_image(tmp_path / "f.png", rgb.astype(float))


def test_writer_refuses_to_clobber_and_duplicates(tmp_path):
    d = tmp_path / "d"
    write_dataset(d, images(1), np.zeros((1, 3)))
    with pytest.raises(FileExistsError, match="overwrite"):
        write_dataset(d, images(1), np.zeros((1, 3)))
    write_dataset(d, images(2), np.zeros((2, 3)), overwrite=True)
    assert len(Dataset(d)) == 2
    other = tmp_path / "other"
    other.mkdir()
    (other / "precious.txt").write_text("x")
    with pytest.raises(FileExistsError, match="not an sfanav dataset"):
        DatasetWriter(other, overwrite=True)
    with DatasetWriter(tmp_path / "w") as w:
        w.add(images(1)[0], frame=0, timestamp=0.0, pose=(0, 0, 0))
        with pytest.raises(ValueError, match="frame 0 of camera 'center' was already written"):
            w.add(images(1)[0], frame=0, timestamp=0.0, pose=(0, 0, 0))
        with pytest.raises(ValueError, match="camera must be .* without commas"):
            w.add(images(1)[0], frame=1, timestamp=0.0, pose=(0, 0, 0), camera="a,b")
        with pytest.raises(ValueError, match="pose"):
            w.add(images(1)[0], frame=1, timestamp=0.0, pose=(0, np.inf, 0))
        with pytest.raises(ValueError, match="unknown extra columns"):
            w.add(images(1)[0], frame=1, timestamp=0.0, pose=(0, 0, 0), segment=3)
    with pytest.raises(ValueError, match="got 2 images for 3 poses"):
        write_dataset(tmp_path / "x", images(2), np.zeros((3, 3)))


def test_reader_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no dataset"):
        Dataset(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="not a dataset: expected metadata.json"):
        Dataset(tmp_path / "empty")
    d = tmp_path / "d"
    write_dataset(d, images(3), np.zeros((3, 3)), timestamps=[0.0, 1.0, 2.0])
    text = (d / "frames.csv").read_text().splitlines()
    # unsorted timestamps
    rows = [text[0], text[1], text[3], text[2]]
    (d / "frames.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(ValueError, match="line 4: timestamp 1.0 is earlier .* must be sorted"):
        Dataset(d)
    # a bad number
    (d / "frames.csv").write_text("\n".join([text[0], text[1].replace(",0.0,", ",abc,", 1)] + text[2:]) + "\n")
    with pytest.raises(ValueError, match="line 2: column 'timestamp' has 'abc', not a number"):
        Dataset(d)
    # a missing column
    (d / "frames.csv").write_text("frame,x\n0,1\n")
    with pytest.raises(ValueError, match="lacks column"):
        Dataset(d)
    (d / "metadata.json").write_text('{"format": "sfanav-dataset", "version": 99}')
    with pytest.raises(ValueError, match="newer than this sfanav"):
        Dataset(d)
    (d / "metadata.json").unlink()
    with pytest.raises(FileNotFoundError, match="metadata.json"):
        Dataset(d)


# ------------------------------------------------------------------ real recordings


def write_csv(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def linear_pose(t):
    """A pose log that is linear in time; the heading wraps through +-pi."""
    return 1.0 + 2.0 * t, -0.5 * t, (3.0 + 0.4 * t + np.pi) % (2 * np.pi) - np.pi


def test_recording_import_interpolates_exactly(tmp_path):
    pose_t = np.array([0.0, 1.0, 2.5, 4.0, 6.0])
    write_csv(tmp_path / "poses.csv", ["timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading"],
              [[t, *linear_pose(t), *linear_pose(t)] for t in pose_t])
    img_dir = tmp_path / "imgs"
    img_dir.mkdir()
    img_t = [0.3, 1.7, 2.5, 3.9, 5.25]
    for i, t in enumerate(img_t):
        write_image(img_dir / f"{t}.png", images(1, seed=i)[0])
    ds = Dataset.from_recording(img_dir, tmp_path / "poses.csv")
    assert len(ds) == 5
    expected = np.array([linear_pose(t) for t in img_t])
    np.testing.assert_allclose(ds.poses[:, :2], expected[:, :2], atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (ds.poses[:, 2] - expected[:, 2]))), 0, atol=1e-12)
    np.testing.assert_allclose(ds.odometry[:, :2], expected[:, :2], atol=1e-12)
    np.testing.assert_array_equal(ds.image(1), images(1, seed=1)[0])
    # the same through an image log CSV, written out as an sfanav dataset
    write_csv(tmp_path / "images.csv", ["timestamp", "image"], [[t, f"imgs/{t}.png"] for t in img_t])
    out = Dataset.from_recording(tmp_path / "images.csv", tmp_path / "poses.csv", out=tmp_path / "ds",
                                 camera="front", condition="cloudy")
    again = Dataset(tmp_path / "ds")
    np.testing.assert_allclose(again.poses, out.poses, atol=1e-12)
    assert set(again.cameras) == {"front"} and set(again.conditions) == {"cloudy"}
    np.testing.assert_array_equal(again.image(4), images(1, seed=4)[0])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=20), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))
def test_heading_interpolation_is_exact_on_linear_motion(ts, w, th0):
    from sfanav.data.dataset import _interp_angle

    tp = np.linspace(0.0, 10.0, 11)
    ang = (th0 + w * tp + np.pi) % (2 * np.pi) - np.pi  # turning at w rad/s, wrapped
    got = _interp_angle(np.array(ts), tp, ang)
    want = th0 + w * np.array(ts)
    assert np.abs(np.angle(np.exp(1j * (got - want)))).max() < 1e-9


def test_recording_errors(tmp_path):
    write_csv(tmp_path / "poses.csv", ["timestamp", "x", "y", "heading"], [[0, 0, 0, 0], [2, 2, 0, 0]])
    img_dir = tmp_path / "imgs"
    img_dir.mkdir()
    for t in (0.5, 3.0):
        write_image(img_dir / f"{t}.png", images(1)[0])
    with pytest.raises(ValueError, match=r"1 image\(s\) lie outside .* first .*3.0.png"):
        Dataset.from_recording(img_dir, tmp_path / "poses.csv")
    assert len(Dataset.from_recording(img_dir, tmp_path / "poses.csv", outside="drop")) == 1
    write_csv(tmp_path / "unsorted.csv", ["timestamp", "x", "y", "heading"], [[0, 0, 0, 0], [2, 1, 0, 0], [1, 2, 0, 0]])
    with pytest.raises(ValueError, match="timestamps must increase strictly; row 3 .* sort the log"):
        Dataset.from_recording(img_dir, tmp_path / "unsorted.csv")
    write_csv(tmp_path / "badrow.csv", ["timestamp", "x", "y", "heading"], [[0, 0, 0, 0], [1, "n/a", 0, 0]])
    with pytest.raises(ValueError, match="line 3: column 'x' has 'n/a', not a number"):
        Dataset.from_recording(img_dir, tmp_path / "badrow.csv")
    write_csv(tmp_path / "short.csv", ["timestamp", "x", "y", "heading"], [[0, 0, 0, 0], [1, 2, 0]])
    with pytest.raises(ValueError, match="line 3: 3 fields, expected 4"):
        Dataset.from_recording(img_dir, tmp_path / "short.csv")
    with pytest.raises(FileNotFoundError, match="no pose log"):
        Dataset.from_recording(img_dir, tmp_path / "missing.csv")
    write_csv(tmp_path / "imglog.csv", ["timestamp", "image"], [[1.0, "imgs/0.5.png"], [0.5, "imgs/3.0.png"]])
    with pytest.raises(ValueError, match="image log .* timestamps must not decrease"):
        Dataset.from_recording(tmp_path / "imglog.csv", tmp_path / "poses.csv")
    write_csv(tmp_path / "imglog2.csv", ["timestamp", "image"], [[1.0, "imgs/nothere.png"]])
    with pytest.raises(FileNotFoundError, match="nothere.png"):
        Dataset.from_recording(tmp_path / "imglog2.csv", tmp_path / "poses.csv")
    write_image(img_dir / "frame_a.png", images(1)[0])
    with pytest.raises(ValueError, match="'frame_a.png' is not a timestamp"):
        Dataset.from_recording(img_dir, tmp_path / "poses.csv")
    with pytest.raises(ValueError, match="heading_unit"):
        Dataset.from_recording(img_dir, tmp_path / "poses.csv", heading_unit="grad")


# ------------------------------------------------------------------ insect-navigation databases


def test_insect_navigation_database(tmp_path):
    db = tmp_path / "db"
    db.mkdir()
    lines = ["X [mm], Y [mm], Z [mm], Heading [degrees], Filename, Grid X, Grid Y, Grid Z"]
    for i, (x, y) in enumerate([(0, 0), (100, 0), (0, 100)]):
        name = f"image_{i:05d}.png"
        write_image(db / name, images(1, seed=i)[0])
        lines.append(f"{x}, {y}, 10, {90 * i}, {name}, {i}, 0, 0")
    (db / "database_entries.csv").write_text("\n".join(lines) + "\n")
    (db / "database_metadata.yaml").write_text(
        '%YAML:1.0\n---\nmetadata:\n   time: "2019-05-01"\n   type: grid\n   camera:\n      name: pixpro\n'
        "   needsUnwrapping: 1\n"
    )
    ds = Dataset(db)
    assert len(ds) == 3
    np.testing.assert_allclose(ds.poses, [[0, 0, 0], [0.1, 0, np.pi / 2], [0, 0.1, np.pi]])
    np.testing.assert_allclose(ds.column("z"), 0.01)
    np.testing.assert_array_equal(ds.column("grid_x"), [0, 1, 2])
    assert ds.metadata["database_metadata"]["camera"]["name"] == "pixpro"
    assert set(ds.runs) == {"grid"} and not ds.has_odometry
    np.testing.assert_array_equal(ds.image(2), images(1, seed=2)[0])
    # a route without metadata, with a bad row
    route = tmp_path / "route"
    route.mkdir()
    (route / "database_entries.csv").write_text(
        "X [mm], Y [mm], Z [mm], Heading [degrees], Filename\n0, 0, 0, 0, a.png\n5, x, 0, 0, b.png\n")
    with pytest.raises(ValueError, match="line 3: column 'Y \\[mm\\]' has 'x', not a number"):
        Dataset(route)
    (route / "database_entries.csv").write_text("X [mm], Y [mm], Filename\n0, 0, a.png\n")
    with pytest.raises(ValueError, match="lacks column.*Heading \\[degrees\\]"):
        Dataset(route)


def test_an_interrupted_writer_leaves_no_dataset(tmp_path):
    from sfanav.data import DatasetWriter

    out = tmp_path / "partial"
    img = np.zeros((4, 8, 3), np.uint8)
    with pytest.raises(KeyboardInterrupt):
        with DatasetWriter(out) as w:
            w.add(img, frame=0, timestamp=0.0, pose=(0, 0, 0))
            raise KeyboardInterrupt  # as Ctrl-C in the middle of sfanav simulate
    assert (out / "frames.csv").exists() and not (out / "metadata.json").exists()
    with pytest.raises(FileNotFoundError, match="no metadata.json"):
        sfanav.data.Dataset(out)


def test_a_frames_table_that_disagrees_with_the_metadata_is_refused(tmp_path):
    from sfanav.data import write_dataset

    out = tmp_path / "d"
    write_dataset(out, [np.zeros((4, 8, 3), np.uint8)] * 3, np.zeros((3, 3)))
    lines = (out / "frames.csv").read_text().splitlines(keepends=True)
    (out / "frames.csv").write_text("".join(lines[:-1]))  # one row lost, as after a kill
    with pytest.raises(ValueError, match="incomplete or altered: metadata.json says 3 images, frames.csv has 2"):
        sfanav.data.Dataset(out)


def test_a_staged_writer_leaves_nothing_until_complete_and_keeps_what_it_replaces(tmp_path):
    from sfanav.data import DatasetWriter

    out = tmp_path / "d"
    img = np.zeros((4, 8, 3), np.uint8)
    with pytest.raises(KeyboardInterrupt):
        with DatasetWriter(out, staged=True) as w:
            w.add(img, frame=0, timestamp=0.0, pose=(0, 0, 0))
            assert w.folder != out and w.folder.parent == tmp_path and w.folder.name.startswith(".d.part-")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    write_dataset(out, images(2), np.zeros((2, 3)))
    with pytest.raises(FileExistsError, match="not empty; pass overwrite=True"):
        DatasetWriter(out, staged=True)
    with pytest.raises(ValueError, match="broken"):
        with DatasetWriter(out, overwrite=True, staged=True) as w:
            w.add(img, frame=0, timestamp=0.0, pose=(0, 0, 0))
            raise ValueError("broken")
    assert len(Dataset(out)) == 2 and sorted(p.name for p in tmp_path.iterdir()) == ["d"]
    with DatasetWriter(out, overwrite=True, staged=True) as w:
        for i in range(3):
            w.add(img, frame=i, timestamp=float(i), pose=(0, 0, 0))
        assert len(Dataset(out)) == 2  # the old one until close
    assert len(Dataset(out)) == 3 and sorted(p.name for p in tmp_path.iterdir()) == ["d"]
    other = tmp_path / "other"
    other.mkdir()
    (other / "precious.txt").write_text("x")
    with pytest.raises(FileExistsError, match="not an sfanav dataset"):
        DatasetWriter(other, overwrite=True, staged=True)
    empty = tmp_path / "empty"
    empty.mkdir()
    with DatasetWriter(empty, staged=True) as w:
        w.add(img, frame=0, timestamp=0.0, pose=(0, 0, 0))
    assert len(Dataset(empty)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "empty", "other"]


# ------------------------------------------------------------------ exact stamps (int64 ns)

UNIX_NS = 1_733_000_000_123_456_789  # a Unix time in ns that float seconds cannot hold exactly


def test_exact_stamps_round_trip_as_int64_nanoseconds(tmp_path):
    ns = [UNIX_NS + k * 33_333_333 for k in range(5)]
    assert any(int(round(v / 1e9 * 1e9)) != v for v in ns)  # float seconds would not do
    img = np.zeros((4, 8, 3), np.uint8)
    with DatasetWriter(tmp_path / "d", exact_stamps=True) as w:
        for i, v in enumerate(ns[:3]):
            w.add(img, frame=i, timestamp=v / 1e9, stamp_ns=v, pose=(i, 0, 0), run="a")
        write_image(tmp_path / "x.png", img)
        w.add_file(tmp_path / "x.png", frame=3, timestamp=ns[3] / 1e9, stamp_ns=np.int64(ns[3]), pose=(3, 0, 0),
                   run="b")
        w.add_encoded((tmp_path / "x.png").read_bytes(), ".png", shape=img.shape, frame=4, timestamp=ns[4] / 1e9,
                      stamp_ns=ns[4], pose=(4, 0, 0), run="b")
    ds = Dataset(tmp_path / "d")
    assert ds.stamps_ns.dtype == np.int64 and ds.stamps_ns.tolist() == ns
    np.testing.assert_allclose(ds.timestamps, np.array(ns) / 1e9, rtol=0, atol=1e-6)
    assert ds.select(run="b").stamps_ns.tolist() == ns[3:]
    assert ds.subset([4, 0]).stamps_ns.tolist() == [ns[4], ns[0]]
    assert ds.metadata["units"]["stamp_ns"] == "ns"
    with open(tmp_path / "d" / "frames.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][:4] == ["frame", "run", "timestamp", "stamp_ns"]
    assert [r[3] for r in rows[1:]] == [str(v) for v in ns]  # the exact integer, readable by anything
    # write_dataset takes them too, and derives the float timestamps from them
    ds = write_dataset(tmp_path / "w", images(5), np.zeros((5, 3)), stamps_ns=np.array(ns, np.int64))
    assert ds.stamps_ns.tolist() == ns
    np.testing.assert_allclose(ds.timestamps, np.array(ns) / 1e9, rtol=0, atol=1e-6)


def test_datasets_without_exact_stamps_still_load(tmp_path):
    ds = write_dataset(tmp_path / "new", images(2), np.zeros((2, 3)), timestamps=[0.0, 0.5])
    assert ds.stamps_ns is None and "stamp_ns" not in (tmp_path / "new" / "frames.csv").read_text()
    assert "stamp_ns" not in ds.metadata["units"]
    old = tmp_path / "old"  # as sfanav wrote datasets before the column existed
    (old / "images").mkdir(parents=True)
    write_image(old / "images" / "000000_center.png", images(1)[0])
    (old / "frames.csv").write_text(
        "frame,run,timestamp,x,y,heading,odom_x,odom_y,odom_heading,camera,condition,image,segment\n"
        "0,train,1733000000.1234568,1.0,2.0,0.5,,,,center,default,images/000000_center.png,3\n")
    (old / "metadata.json").write_text('{"format": "sfanav-dataset", "version": 1, "units": {"timestamp": "s"}, '
                                       '"n_images": 1}')
    ds = Dataset(old)
    assert ds.stamps_ns is None and ds.timestamps.tolist() == [1733000000.1234568]
    assert ds.column("segment").tolist() == [3]


def test_exact_stamps_are_checked(tmp_path):
    img = np.zeros((4, 8, 3), np.uint8)
    with DatasetWriter(tmp_path / "plain") as w:
        with pytest.raises(ValueError, match="stamp_ns given, but the writer has no exact stamps"):
            w.add(img, frame=0, timestamp=1.0, stamp_ns=10**9, pose=(0, 0, 0))
    with DatasetWriter(tmp_path / "exact", exact_stamps=True) as w:
        with pytest.raises(ValueError, match="give stamp_ns"):
            w.add(img, frame=0, timestamp=1.0, pose=(0, 0, 0))
        with pytest.raises(TypeError, match="stamp_ns must be an integer"):
            w.add(img, frame=0, timestamp=1.0, stamp_ns=1e9, pose=(0, 0, 0))
        with pytest.raises(ValueError, match="stamp_ns must be at least 0"):
            w.add(img, frame=0, timestamp=-1.0, stamp_ns=-10**9, pose=(0, 0, 0))
        with pytest.raises(ValueError, match=r"timestamp 1.5 s and stamp_ns 1000000000 \(1.0 s\) disagree"):
            w.add(img, frame=0, timestamp=1.5, stamp_ns=10**9, pose=(0, 0, 0))
        w.add(img, frame=0, timestamp=UNIX_NS / 1e9, stamp_ns=UNIX_NS, pose=(0, 0, 0))
        w.add(img, frame=1, timestamp=UNIX_NS / 1e9, stamp_ns=UNIX_NS + 1, pose=(0, 0, 0))
    with pytest.raises(ValueError, match="clash with the standard columns"):
        DatasetWriter(tmp_path / "x", extra_columns=["stamp_ns"])
    d = tmp_path / "exact"
    good = (d / "frames.csv").read_text()
    lines = good.splitlines()
    for bad, words in [(lines[2].replace(str(UNIX_NS + 1), "1733000000123456789.0"), "line 3: column 'stamp_ns' has"),
                       (lines[2].replace(str(UNIX_NS + 1), ""), "line 3: column 'stamp_ns' has '', not an integer"),
                       (lines[2].replace(str(UNIX_NS + 1), str(UNIX_NS + 10**6)),
                        "line 3: timestamp 1733000000.1234567 s and stamp_ns 1733000000124456789"),
                       (lines[2].replace(str(UNIX_NS + 1), str(UNIX_NS - 1)),
                        "line 3: stamp_ns 1733000000123456788 is earlier than the previous image"),
                       (lines[2].replace(str(UNIX_NS + 1), str(2**64)),
                        "line 3: column 'stamp_ns' has 18446744073709551616, out of the int64 range")]:
        (d / "frames.csv").write_text("\n".join([lines[0], lines[1], bad]) + "\n")
        with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
            Dataset(d)
    (d / "frames.csv").write_text(good)
    assert Dataset(d).stamps_ns.tolist() == [UNIX_NS, UNIX_NS + 1]

