"""Every public function of lidar_noise: configurations, apply on every input layout,
reproducibility for any thread count, reading and writing, the pipeline's steps, and the
exceptions bad input raises."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import lidar_noise as ln
from conftest import FIXTURES, REPO

RAIN = """
seed = 7
[[noise]]
type = "rain"
rate_mm_h = 25.0
"""

WEATHER = REPO / "configs" / "adverse-weather.toml"


def scan(n=5000, seed=1, ring=False):
    """A synthetic HDL-32E-like scan: points on the beams' cones out to 5-60 m."""
    rng = np.random.default_rng(seed)
    elev = np.array(ln_elevations())
    laser = rng.integers(0, 32, n)
    az = rng.uniform(0, 360, n)
    r = rng.uniform(5, 60, n)
    el = np.radians(elev[laser])
    a = np.radians(az)
    pts = np.stack(
        [r * np.cos(el) * np.cos(a), -r * np.cos(el) * np.sin(a), r * np.sin(el), rng.uniform(0, 255, n)],
        axis=1,
    ).astype(np.float32)
    if ring:
        rings = np.argsort(np.argsort(elev, kind="stable"), kind="stable")[laser]
        pts = np.concatenate([pts, rings[:, None].astype(np.float32)], axis=1)
    return pts


def ln_elevations():
    # HDL-32E manual, laser ids 0..31.
    return [
        -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00,
        -2.67, -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00,
        -16.00, 5.33, -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
    ]


# --- configurations -------------------------------------------------------------------


def test_from_toml_reads_text_and_paths_alike():
    from_text = ln.Chain.from_toml(WEATHER.read_text())
    from_path = ln.Chain.from_toml(WEATHER)
    from_str = ln.Chain.from_toml(str(WEATHER))
    assert from_text.stages == from_path.stages == from_str.stages
    assert from_path.stages and from_path.seed == from_text.seed
    pts = scan()
    a = from_text.apply(pts, frame=3)
    b = from_path.apply(pts, frame=3)
    assert a.tobytes() == b.tobytes()


def test_from_dict_is_the_toml_laid_out_as_a_dict():
    d = ln.Chain.from_dict({"seed": 7, "noise": [{"type": "rain", "rate_mm_h": 25.0}]})
    t = ln.Chain.from_toml(RAIN)
    assert d.stages == t.stages == ["rain"]
    assert d.effective_toml == t.effective_toml
    pts = scan()
    assert d.apply(pts).tobytes() == t.apply(pts).tobytes()


def test_validate_gives_the_warnings_and_bad_options_raise_with_key_and_line():
    assert isinstance(ln.Chain.from_toml(RAIN).validate(), list)
    bad = RAIN + "rate_mm_hh = 3.0\n"
    with pytest.raises(ValueError) as e:
        ln.Chain.from_toml(bad)
    msg = str(e.value)
    assert "rate_mm_hh" in msg and "line 6" in msg, msg
    with pytest.raises(ValueError, match="rate_mm_h"):
        ln.Chain.from_dict({"noise": [{"type": "rain", "rate_mm_h": -1.0}]})
    with pytest.raises(ValueError, match="nosuchstage"):
        ln.Chain.from_dict({"noise": [{"type": "nosuchstage"}]})
    # Every modelled sensor is taken (test_sensors.py); other names are refused.
    assert ln.Chain.from_toml(RAIN, sensor="vlp16").lasers == 16
    with pytest.raises(ValueError, match="sensor"):
        ln.Chain.from_toml(RAIN, sensor="vlp64")
    with pytest.raises(FileNotFoundError):
        ln.Chain.from_toml("no/such/config.toml")


# --- apply ----------------------------------------------------------------------------


def test_apply_on_plain_points_keeps_rows_in_input_order():
    pts = scan()
    out = ln.Chain.from_toml(RAIN).apply(pts, seed=3)
    assert out.dtype == ln.APPLIED_DTYPE
    n = len(pts)
    assert len(out) >= n
    clean = out[:n]
    # Row i is point i: its clean range is the point's norm, wherever the noise put it.
    norm = np.linalg.norm(pts[:, :3].astype(np.float64), axis=1)
    assert np.allclose(clean["range_clean"], norm, rtol=1e-6)
    # Rain drops and replaces some returns, leaves most, and the mask says which.
    fates = np.bincount(out["fate"], minlength=6)
    assert fates[0] > 0.5 * n and fates[0] < n
    assert (out["kept"] == np.isin(out["fate"], [0, 4, 5])).all()
    assert (out["fate"][n:] == 5).all()
    # Kept returns move along their beam only.
    kept = clean[clean["fate"] == 0]
    scale = kept["range"] / kept["range_clean"]
    src = pts[clean["fate"] == 0]
    assert np.allclose(kept["x"], src[:, 0] * scale, rtol=1e-5, atol=1e-5)


def test_apply_accepts_every_layout_of_the_same_points():
    chain = ln.Chain.from_toml(RAIN)
    pts = scan(ring=True)
    rec = np.zeros(len(pts), dtype=ln.POINT_DTYPE)
    for i, name in enumerate(("x", "y", "z", "intensity", "ring")):
        rec[name] = pts[:, i]
    a = chain.apply(pts, seed=1, frame=2)
    b = chain.apply(rec, seed=1, frame=2)
    c = chain.apply(pts.astype(np.float64), seed=1, frame=2)
    assert a.tobytes() == b.tobytes() == c.tobytes()
    # Rings are used: without them lasers come from the elevations, which here agree.
    d = chain.apply(pts[:, :4], seed=1, frame=2)
    assert (d["laser"][: len(pts)] == a["laser"][: len(pts)]).all()


def test_seed_and_frame_select_the_streams():
    chain = ln.Chain.from_toml(RAIN)
    pts = scan()
    base = chain.apply(pts, seed=1, frame=0)
    assert chain.apply(pts, seed=1, frame=0).tobytes() == base.tobytes()
    assert chain.apply(pts, seed=2, frame=0).tobytes() != base.tobytes()
    assert chain.apply(pts, seed=1, frame=1).tobytes() != base.tobytes()
    # The configuration's seed is the default.
    assert chain.apply(pts, frame=0).tobytes() == chain.apply(pts, seed=7, frame=0).tobytes()


def test_the_same_bytes_for_any_thread_count():
    chain = ln.Chain.from_toml(WEATHER)
    frames = ln.read(FIXTURES / "crossroad.pcap")
    for f in frames:
        one = chain.apply(f.points, frame=f.index, threads=1)
        two = chain.apply(f.points, frame=f.index, threads=2)
        four = chain.apply(f.points, frame=f.index, threads=4)
        assert one.tobytes() == two.tobytes() == four.tobytes()
    # And between processes with RAYON_NUM_THREADS set, as a data loader's workers are.
    code = textwrap.dedent(
        f"""
        import hashlib, lidar_noise as ln
        c = ln.Chain.from_toml({str(WEATHER)!r})
        h = hashlib.sha256()
        for f in ln.read({str(FIXTURES / 'parking.pcap')!r}):
            h.update(c.apply(f.points, frame=f.index).tobytes())
        print(h.hexdigest())
        """
    )
    digests = set()
    for n in ("1", "3"):
        env = dict(os.environ, RAYON_NUM_THREADS=n)
        run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        digests.add(run.stdout.strip())
    assert len(digests) == 1, digests


# --- bad input ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "points, message",
    [
        (np.zeros((10, 3), np.float32), "shape"),
        (np.zeros((10, 6), np.float32), "shape"),
        (np.zeros(10, np.float32), "shape"),
        (np.zeros((10, 4), np.int32), "dtype"),
        ([[1.0, 2.0, 3.0, 4.0]], "numpy array"),
        (np.zeros(3, dtype=[("a", "f4")]), "x, y, z missing"),
    ],
)
def test_bad_arrays_raise_value_error(points, message):
    with pytest.raises(ValueError, match=message):
        ln.Chain.from_toml(RAIN).apply(points)


def test_a_c_ordered_float32_array_gives_what_its_columns_give():
    """A C-ordered float32 (N, 4) or (N, 5) array is read whole, row by row; every other
    layout through its columns. The same points give the same bytes either way, with
    the weather chain's echoes (the slots depend on every point's ring and position)."""
    chain = ln.Chain.from_toml(REPO / "configs" / "adverse-weather.toml")
    for ring in (False, True):
        pts = scan(3000, seed=5, ring=ring)
        assert pts.dtype == np.float32 and pts.flags.c_contiguous
        whole = chain.apply(pts, frame=2)
        for other in (np.asfortranarray(pts), pts.astype(np.float64), np.hstack([pts, pts])[:, : pts.shape[1]]):
            assert not (other.dtype == np.float32 and other.flags.c_contiguous)
            assert whole.tobytes() == chain.apply(other, frame=2).tobytes()
        a, order_a = ln.points_to_returns(pts)
        b, order_b = ln.points_to_returns(np.asfortranarray(pts))
        assert a.tobytes() == b.tobytes() and np.array_equal(order_a, order_b)
    # The first bad ring is named from the whole array too, after the points before it.
    pts = scan(100, ring=True)
    pts[9, 4] = 70000
    pts[30, 4] = 0.5
    with pytest.raises(ValueError, match=r"point 9 \(0-based\): ring 70000 is out of range"):
        chain.apply(pts)


def test_nan_and_bad_rings_name_the_point():
    chain = ln.Chain.from_toml(RAIN)
    pts = scan(100)
    pts[42, 1] = np.nan
    with pytest.raises(ValueError, match=r"point 42 \(0-based\): y is NaN"):
        chain.apply(pts)
    pts = scan(100, ring=True)
    pts[7, 4] = 32
    with pytest.raises(ValueError, match=r"point 7 \(0-based\): ring 32 is out of range"):
        chain.apply(pts)
    pts[7, 4] = 1.5
    with pytest.raises(ValueError, match=r"point 7 \(0-based\): ring 1.5 is not a whole number"):
        chain.apply(pts)
    pts[7, 4] = 3
    pts[11, 4] = np.nan
    with pytest.raises(ValueError, match=r"point 11 \(0-based\): ring NaN is not a whole number"):
        chain.apply(pts)
    pts[11, 4] = -1
    with pytest.raises(ValueError, match=r"point 11 \(0-based\): ring -1 is out of range"):
        chain.apply(pts)
    pts[11, 4] = 70000
    with pytest.raises(ValueError, match=r"point 11 \(0-based\): ring 70000 is out of range"):
        chain.apply(pts.astype(np.float64))
    pts[11, 4] = 3e9
    with pytest.raises(ValueError, match=r"point 11 \(0-based\): ring 3000000000 is out of range"):
        chain.apply(pts)
    pts[11, 4] = np.inf
    with pytest.raises(ValueError, match=r"point 11 \(0-based\): ring inf is not a whole number"):
        chain.apply(pts)
    ret = ln.read(FIXTURES / "crossroad.pcap")[0].points.copy()
    ret["range"][5] = np.inf
    with pytest.raises(ValueError, match=r"point 5 \(0-based\): range"):
        chain.apply(ret)
    ret = ln.read(FIXTURES / "crossroad.pcap")[0].points.copy()
    ret["kind"][9] = 7
    with pytest.raises(ValueError, match=r"point 9 \(0-based\): kind 7"):
        chain.apply(ret)
    with pytest.raises(ValueError, match="seed"):
        chain.apply(scan(10), seed=-1)
    with pytest.raises(ValueError, match="seed"):
        chain.apply(scan(10), seed=2**63)
    with pytest.raises(ValueError, match="rotation_hz"):
        chain.apply(scan(10), rotation_hz=50.0)
    with pytest.raises(ValueError, match="threads"):
        chain.apply(scan(10), threads=0)


def test_empty_input_gives_an_empty_result():
    out = ln.Chain.from_toml(RAIN).apply(np.zeros((0, 4), np.float32))
    assert out.dtype == ln.APPLIED_DTYPE


# --- points to returns ----------------------------------------------------------------


def test_points_to_returns_puts_points_on_the_firing_grid():
    # Firing k of a 10 Hz turn starts at 360 k / 2170 degrees, laser l fires l * 1.152 us
    # later (3.6e-3 degrees a microsecond).
    k, laser, r = 100, 5, 20.0
    az = np.radians(k * 360.0 / 2170 + laser * 1.152 * 3.6e-3)
    el = np.radians(ln_elevations()[laser])
    p = np.array([[r * np.cos(el) * np.cos(az), -r * np.cos(el) * np.sin(az), r * np.sin(el), 50.0]], np.float32)
    ret, order = ln.points_to_returns(p)
    assert ret.dtype == ln.RETURN_DTYPE and list(order) == [0]
    assert (ret["laser"][0], ret["packet"][0], ret["block"][0]) == (laser, k // 12, k % 12)
    assert abs(ret["time"][0] - (k * 46.08 + laser * 1.152) * 1e-6) < 1e-12
    assert ret["intensity"][0] == 50
    half, _ = ln.points_to_returns(np.array([[5.0, 0, 0, 0.5]], np.float32), intensity_scale="unit")
    assert half["intensity"][0] == 128


def test_points_with_a_time_field_are_placed_by_time():
    # Point 1's azimuth says firing 100, its time (seconds after point 0's, which fired
    # first) firing 300: a time field places points by time, as `run` places a file's.
    def at(k, laser, r=20.0):
        az = np.radians(k * 360.0 / 2170 + laser * 1.152 * 3.6e-3)
        el = np.radians(ln_elevations()[laser])
        return (r * np.cos(el) * np.cos(az), -r * np.cos(el) * np.sin(az), r * np.sin(el))
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("time", "<f8")]
    p = np.array([(*at(0, 0), 50.0, 0.0), (*at(100, 5), 50.0, (300 * 46.08 + 5 * 1.152) * 1e-6)], dtype)
    ret, order = ln.points_to_returns(p)
    assert list(order) == [0, 1]
    assert (ret["packet"][1], ret["block"][1]) == (300 // 12, 300 % 12)
    assert abs(ret["time"][1] - (300 * 46.08 + 5 * 1.152) * 1e-6) < 1e-9
    untimed = p[["x", "y", "z", "intensity"]]
    ret, _ = ln.points_to_returns(untimed)
    assert (ret["packet"][1], ret["block"][1]) == (100 // 12, 100 % 12)
    p["time"][1] = np.nan
    with pytest.raises(ValueError, match="point 1 .*time is NaN"):
        ln.points_to_returns(p)


# --- reading and writing --------------------------------------------------------------


def test_read_a_capture_gives_its_frames():
    # The return-for-return check against the CLI is in test_cli_equivalence.py.
    frames = ln.read(FIXTURES / "crossroad.pcap")
    assert [f.index for f in frames] == [0, 1]
    assert all(f.points.dtype == ln.RETURN_DTYPE and not f.partial for f in frames)
    assert len(frames[0].points) > 20000
    p = frames[0].points
    assert np.allclose(np.hypot(np.hypot(p["x"], p["y"]), p["z"]), p["range"], atol=1e-3)
    # Captures are decoded as the HDL-32E's only: another sensor is refused for them.
    with pytest.raises(ValueError, match="sensor"):
        ln.read(FIXTURES / "crossroad.pcap", sensor="vlp16")


def test_read_and_write_point_cloud_files(tmp_path):
    pts = scan(300, ring=True)
    for name in ("scan.pcd.bin", "scan.bin"):
        path = tmp_path / name
        ln.write(path, pts if name.endswith(".pcd.bin") else pts[:, :4])
        (frame,) = ln.read(path)
        assert frame.index == 0 and len(frame.points) == 300
        assert np.array_equal(frame.points["x"], pts[:, 0])
        assert np.array_equal(frame.points["intensity"], pts[:, 3])
        if name.endswith(".pcd.bin"):
            assert frame.intensity_scale == "byte"
            assert np.array_equal(frame.points["ring"], pts[:, 4].astype(np.int64))
        else:
            assert frame.intensity_scale == "unit"
    # A KITTI file straight into apply, with its scale.
    (frame,) = ln.read(tmp_path / "scan.bin")
    out = ln.Chain.from_toml(RAIN).apply(frame.points, intensity_scale=frame.intensity_scale)
    assert len(out) >= 300


def test_write_ply_of_applied_returns_has_the_fate_columns(tmp_path):
    from conftest import read_ply

    f = ln.read(FIXTURES / "parking.pcap")[0]
    out = ln.Chain.from_toml(RAIN).apply(f.points, frame=f.index)
    ln.write(tmp_path / "out.ply", out)
    back = read_ply(tmp_path / "out.ply")
    assert len(back) == len(out)
    for name in ("x", "y", "z", "intensity", "fate", "cause", "range_clean"):
        assert np.array_equal(back[name], out[name].astype(back[name].dtype)), name
    ln.write(tmp_path / "plain.ply", scan(50))
    assert len(read_ply(tmp_path / "plain.ply")) == 50


def test_file_errors_are_os_errors_and_bad_files_value_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        ln.read(tmp_path / "missing.pcap")
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\0" * 17)
    with pytest.raises(ValueError, match="17 bytes is not a whole number of 16-byte"):
        ln.read(bad)
    with pytest.raises(ValueError, match="extension"):
        ln.write(tmp_path / "x.xyz", scan(5))
    with pytest.raises(OSError):
        ln.write(tmp_path / "no" / "such" / "dir.ply", scan(5))
    assert not list((tmp_path).glob("no*"))


# --- pipeline steps -------------------------------------------------------------------


def test_cluster_finds_separate_blobs():
    rng = np.random.default_rng(0)
    a = rng.normal([10, 0, 0], 0.1, (50, 3))
    b = rng.normal([20, 5, 0], 0.1, (60, 3))
    lone = np.array([[40.0, 40.0, 0.0]])
    pts = np.concatenate([a, b, lone]).astype(np.float32)
    labels = ln.cluster(pts, cutoff_m=0.5, min_points=5)
    assert labels.dtype == np.int32
    assert len(set(labels[:50])) == 1 and len(set(labels[50:110])) == 1
    assert labels[0] != labels[50] and labels[110] == -1
    with pytest.raises(ValueError, match="cutoff_mm"):
        ln.cluster(pts, cutoff_mm=0.5)


def test_ground_labels_a_flat_road_and_not_a_wall():
    # A road 1.8 m under the sensor and a wall 8 m ahead, both on the beams' cones.
    pts = []
    for laser, e in enumerate(ln_elevations()):
        for az in np.arange(0.0, 360.0, 0.5):
            a, el = np.radians(az), np.radians(e)
            if e < -3:
                r = 1.8 / np.sin(-el)
                if r * np.cos(el) > 30:
                    continue
            else:
                continue
            pts.append([r * np.cos(el) * np.cos(a), -r * np.cos(el) * np.sin(a), -1.8, 100.0])
    road = len(pts)
    for z in np.arange(-1.7, 2.0, 0.1):
        for y in np.arange(-3, 3, 0.1):
            pts.append([8.0, y, z, 100.0])
    pts = np.array(pts, np.float32)
    for method in ("patchwork", "ransac", "range-image"):
        g = ln.ground(pts, method=method)
        assert g.dtype == np.bool_ and len(g) == len(pts)
        assert g[:road].mean() > 0.8, method
        assert g[road:][pts[road:, 2] > -1.2].mean() < 0.1, method
    assert not ln.ground(pts, method="none").any()
    with pytest.raises(ValueError, match="method"):
        ln.ground(pts, method="magic")


def test_detect_objects_runs_the_pipeline():
    f = ln.read(FIXTURES / "crossroad.pcap")[0]
    out, clusters = ln.detect_objects(f.points, frame=f.index)
    assert (out["fate"] != 5).all()  # no noise: nothing added
    assert out["ground"].any() and (out["cluster"] >= 0).any()
    assert clusters and all("object" in c for c in clusters)
    ids = {c["id"] for c in clusters} if "id" in clusters[0] else None
    if ids is not None:
        assert set(out["cluster"][out["cluster"] >= 0]) <= ids


# --- sweep ----------------------------------------------------------------------------


def test_sweep_gives_the_commands_tidy_table(cli, tmp_path):
    import csv

    args = dict(vary={"rain.rate_mm_h": [0, 5]}, seeds="1..2", frames="0..1")
    rows = ln.sweep(FIXTURES / "crossroad.pcap", REPO / "configs" / "rain.toml", as_dataframe=False, **args)
    subprocess.run(
        [cli, "-q", "sweep", str(FIXTURES / "crossroad.pcap"), "-c", str(REPO / "configs" / "rain.toml"),
         "--vary", "rain.rate_mm_h=0,5", "--seeds", "1..2", "--frames", "0..1", "-o", str(tmp_path / "s")],
        check=True,
    )
    with open(tmp_path / "s" / "sweep.csv", newline="") as f:
        expected = list(csv.DictReader(f))
    assert len(rows) == len(expected) == 2 * 2 * 2  # frames x rates x seeds
    for got, want in zip(rows, expected):
        for k, v in want.items():
            g = got[k]
            if isinstance(g, bool):
                assert str(g).lower() == v, k
            elif g is None:
                assert v == "", k
            else:
                assert g == type(g)(v), (k, g, v)
    assert {r["rain.rate_mm_h"] for r in rows} == {0, 5}
    with pytest.raises(ValueError, match="rain.rate_mm_hh"):
        ln.sweep(FIXTURES / "crossroad.pcap", REPO / "configs" / "rain.toml", vary={"rain.rate_mm_hh": [1]}, as_dataframe=False)
    with pytest.raises(OSError):
        ln.sweep(FIXTURES / "missing.pcap", as_dataframe=False)


def test_altered_returns_raise_or_run_never_panic():
    # Returns with fields changed at random (a fixed seed): every chain either runs or
    # raises ValueError; a Rust panic would surface as pyo3's PanicException (a
    # BaseException). Mixed return kinds once made the echo resolution index an empty
    # dual slot entry (src/noise/spurious.rs, resolve_slot).
    frame = ln.read(FIXTURES / "crossroad.pcap")[1].points
    chains = [ln.Chain.from_toml(p) for p in sorted((REPO / "configs").glob("*.toml"))]
    rng = np.random.default_rng(0)
    for trial in range(12):
        p = frame[rng.choice(len(frame), 3000, replace=False)]
        p.sort(order=["packet", "block", "laser"])
        for name in ("packet", "block", "ring", "raw_distance", "intensity", "kind"):
            if rng.random() < 0.4:
                hi = 4 if name == "kind" else np.iinfo(p[name].dtype).max
                p[name][rng.integers(0, len(p), 50)] = rng.integers(0, hi, 50)
        for name in ("azimuth", "elevation", "range", "x", "time"):
            if rng.random() < 0.3:
                p[name][rng.integers(0, len(p), 50)] = rng.uniform(-1e6, 1e6, 50)
        for chain in chains:
            try:
                chain.apply(p, frame=int(rng.integers(0, 1000)))
            except ValueError:
                pass


def test_records_in_any_layout_match_the_aligned_one():
    """The compiled side writes APPLIED_DTYPE's aligned layout by a fast path and any
    other layout it is given by the general one: both must give the same values (here a
    layout with the fields reversed, 8-byte slots and 16 spare bytes)."""
    chain = ln.Chain.from_toml(RAIN)
    pts = scan(3000, ring=True)
    want = chain.apply(pts, seed=4, frame=2)
    names = list(ln.APPLIED_DTYPE.names)
    layout = {n: 8 * k for k, n in enumerate(reversed(names))}
    layout["__itemsize__"] = 8 * len(names) + 16
    dtype = np.dtype(
        {
            "names": names,
            "formats": [ln.APPLIED_DTYPE[n] for n in names],
            "offsets": [layout[n] for n in names],
            "itemsize": layout["__itemsize__"],
        }
    )
    _kind, cols = ln._columns(pts)
    raw = chain._core.apply_points(cols, 4, 2, 10.0, "byte", None, layout)
    got = raw.view(dtype)
    assert len(got) == len(want) == len(pts)
    assert (want["range"] != want["range_clean"]).any()  # the rain moved points
    for n in names:
        assert np.array_equal(got[n], want[n], equal_nan=True), n
