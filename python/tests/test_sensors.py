"""Chains for every sensor the library models (`sensor=`): a 64-laser chain on points on
the HDL-64E's beams, per-laser options checked against the sensor's lasers, unknown
sensor names refused, and `lidar-noise run` on a KITTI scan (an HDL-64E's) giving the
fates `Chain.apply(..., sensor="hdl64e")` gives."""

import csv
import subprocess

import numpy as np
import pytest

import lidar_noise as ln
from conftest import REPO

WEATHER = REPO / "configs" / "adverse-weather.toml"

# The `--sensor` names with the model name and laser count each means.
SENSORS = {
    "hdl32e": ("HDL-32E", 32),
    "vlp16": ("VLP-16", 16),
    "puck-hi-res": ("Puck Hi-Res", 16),
    "vlp32c": ("VLP-32C", 32),
    "hdl64e": ("HDL-64E S2", 64),
    "hdl64e-s3": ("HDL-64E S3", 64),
}

OCCLUDE_40 = """
seed = 11
[[noise]]
type = "occlusion"
lasers = [40]
"""

RAIN = """
seed = 7
[[noise]]
type = "rain"
rate_mm_h = 25.0
"""


def beam_scan(sensor, n=6000, seed=1, ring=False):
    """Points on the beams of `sensor` (the library's elevation table, laser ids 0..n-1)
    out to 5-60 m, and the laser each was put on. With `ring`, a fifth column holds each
    point's ring (0 = lowest beam)."""
    _name, lasers, elevations = ln._sensor_model(sensor)
    elev = np.array(elevations)
    rng = np.random.default_rng(seed)
    laser = rng.integers(0, lasers, n)
    az = np.radians(rng.uniform(0, 360, n))
    r = rng.uniform(5, 60, n)
    el = np.radians(elev[laser])
    pts = np.stack(
        [r * np.cos(el) * np.cos(az), -r * np.cos(el) * np.sin(az), r * np.sin(el), rng.uniform(0, 1, n)],
        axis=1,
    ).astype(np.float32)
    if ring:
        rings = np.argsort(np.argsort(elev, kind="stable"), kind="stable")[laser]
        pts = np.concatenate([pts, rings[:, None].astype(np.float32)], axis=1)
    return pts, laser


@pytest.mark.parametrize("sensor", sorted(SENSORS))
def test_every_modelled_sensor_gives_a_chain_for_its_lasers(sensor):
    model, lasers = SENSORS[sensor]
    chain = ln.Chain.from_toml(RAIN, sensor=sensor)
    assert (chain.sensor, chain.lasers) == (model, lasers)
    # The model name is a sensor name too, and the dict form takes the sensor alike.
    assert ln.Chain.from_toml(RAIN, sensor=model).sensor == model
    assert ln.Chain.from_dict({"seed": 7, "noise": [{"type": "rain", "rate_mm_h": 25.0}]}, sensor=sensor).lasers == lasers
    pts, laser = beam_scan(sensor, 3000)
    out = chain.apply(pts, seed=2, intensity_scale="unit")
    n = len(pts)
    assert len(out) >= n and (out["laser"] < lasers).all()
    # Points on the table's beams go to the laser they were put on.
    assert (out["laser"][:n] == laser).all()
    returns, order = ln.points_to_returns(pts, intensity_scale="unit", sensor=sensor)
    assert (returns["laser"] == laser[order]).all()


def test_a_64_laser_chain_occludes_exactly_the_returns_of_laser_40():
    chain = ln.Chain.from_toml(OCCLUDE_40, sensor="hdl64e")
    assert chain.lasers == 64
    pts, laser = beam_scan("hdl64e", 8000)
    assert (laser == 40).sum() > 50 and (laser > 31).sum() > 3000
    out = chain.apply(pts, intensity_scale="unit")
    assert len(out) == len(pts)  # occlusion adds nothing
    assert (out["laser"] == laser).all()
    occluded = out["fate"] == ln.FATES.index("occluded")
    assert (occluded == (laser == 40)).all()
    # Rings 0..63 place the same points on the same lasers.
    with_rings, _ = beam_scan("hdl64e", 8000, ring=True)
    ringed = chain.apply(with_rings, intensity_scale="unit")
    assert ringed.tobytes() == out.tobytes()
    # The same chain on the returns themselves (laser ids up to 63), and detect.
    returns, _order = ln.points_to_returns(pts, intensity_scale="unit", sensor="hdl64e")
    again = chain.apply(returns)
    assert ((again["fate"] == 1) == (returns["laser"] == 40)).all()
    detected, _clusters = chain.detect(returns)
    assert (detected["fate"] == again["fate"]).all()


def test_rings_and_laser_ids_past_the_sensors_lasers_name_the_point():
    pts, _ = beam_scan("hdl64e", 100, ring=True)
    pts[7, 4] = 64
    with pytest.raises(ValueError, match=r"point 7 \(0-based\): ring 64 is out of range for the HDL-64E S2"):
        ln.Chain.from_toml(RAIN, sensor="hdl64e").apply(pts)
    pts[:, 4] %= 16
    pts[7, 4] = 16
    with pytest.raises(ValueError, match=r"point 7 \(0-based\): ring 16 is out of range for the VLP-16"):
        ln.Chain.from_toml(RAIN, sensor="vlp16").apply(pts)
    returns, _ = ln.points_to_returns(beam_scan("hdl64e", 100)[0], sensor="hdl64e")
    i = int(np.flatnonzero(returns["laser"] >= 32)[0])
    with pytest.raises(ValueError, match=rf"point {i} \(0-based\): laser \d+ is out of range \(0 to 31\)"):
        ln.Chain.from_toml(RAIN).apply(returns)


def test_per_laser_options_that_do_not_fit_the_sensor_raise():
    with pytest.raises(ValueError, match="lasers names 40") as e:
        ln.Chain.from_toml(OCCLUDE_40, sensor="hdl32e")
    assert "HDL-32E" in str(e.value) and "occlusion" in str(e.value), str(e.value)
    with pytest.raises(ValueError, match="lasers names 40"):
        ln.Chain.from_toml(OCCLUDE_40)  # the HDL-32E unless said
    with pytest.raises(ValueError, match="lasers names 40"):
        ln.Chain.from_dict({"noise": [{"type": "occlusion", "lasers": [40]}]}, sensor="vlp16")
    # One given value per laser: 32 fit the HDL-32E, not the HDL-64E.
    diode = {"noise": [{"type": "laser_diode", "power_factors": [1.0] * 32}]}
    assert ln.Chain.from_dict(diode, sensor="hdl32e").stages == ["laser_diode"]
    with pytest.raises(ValueError, match="power_factors"):
        ln.Chain.from_dict(diode, sensor="hdl64e")


def test_unknown_sensors_raise_value_error_listing_the_names(tmp_path):
    for call in (
        lambda: ln.Chain.from_toml(RAIN, sensor="vlp64"),
        lambda: ln.Chain.from_dict({}, sensor="vlp64"),
        lambda: ln.points_to_returns(beam_scan("hdl32e", 10)[0], sensor="vlp64"),
        lambda: ln.ground(beam_scan("hdl32e", 10)[0], sensor="vlp64"),
    ):
        with pytest.raises(ValueError, match="vlp64.*hdl32e.*hdl64e"):
            call()
    with pytest.raises(ValueError, match="sensor"):
        ln.Chain.from_toml(RAIN, sensor=64)
    path = tmp_path / "scan.bin"
    ln.write(path, beam_scan("hdl64e", 50)[0])
    with pytest.raises(ValueError, match="vlp64"):
        ln.read(path, sensor="vlp64")


def test_read_takes_any_modelled_sensor_for_point_clouds_and_the_hdl32e_for_captures(tmp_path):
    from conftest import FIXTURES

    path = tmp_path / "scan.bin"
    pts, _ = beam_scan("hdl64e", 50)
    ln.write(path, pts)
    for sensor in SENSORS:
        (frame,) = ln.read(path, sensor=sensor)
        assert np.array_equal(frame.points["x"], pts[:, 0])
    capture = FIXTURES / "crossroad.pcap"
    assert len(ln.read(capture, sensor="hdl32e")) == len(ln.read(capture))
    for sensor in ("vlp16", "hdl64e"):
        with pytest.raises(ValueError, match="HDL-32E"):
            ln.read(capture, sensor=sensor)


def test_ground_and_detect_objects_place_points_on_the_given_sensor():
    pts, laser = beam_scan("hdl64e", 3000)
    a = ln.ground(pts, method="range-image", sensor="hdl64e")
    returns, order = ln.points_to_returns(pts, sensor="hdl64e")
    b = ln.ground(returns, method="range-image", sensor="hdl64e")
    assert np.array_equal(a[order], b)
    out, _ = ln.detect_objects(pts, sensor="hdl64e")
    assert (out["laser"] == laser[order]).all()  # rows in firing order
    chain = ln.Chain.from_toml("", sensor="hdl64e")
    same, _ = ln.detect_objects(pts, config=chain)
    assert same.tobytes() == out.tobytes()
    with pytest.raises(ValueError, match="HDL-64E S2"):
        ln.detect_objects(pts, config=chain, sensor="hdl32e")


def read_fates(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_run_on_a_kitti_scan_gives_the_points_and_fates_of_a_64_laser_chain(cli, tmp_path):
    """`run --sensor hdl64e` takes a KITTI .bin as an HDL-64E S2 scan at 10 Hz with 0-1
    intensities: the points it writes back and their fates are those `apply` gives with
    sensor="hdl64e", bit for bit (fog, rain and snow draw from the seed's streams and
    put echoes in empty slots of all 64 lasers, fog's a chance per beam under the
    receiver's noise; laser 40 is occluded)."""
    config = tmp_path / "weather-occlusion.toml"
    config.write_text(WEATHER.read_text() + OCCLUDE_40.replace("seed = 11\n", ""))
    pts, laser = beam_scan("hdl64e", 8000, seed=3)
    scan = tmp_path / "000000.bin"
    ln.write(scan, pts)
    out = tmp_path / "out"
    # --sensor said, not left to run's default for KITTI scans (which may become a table
    # of KITTI's own unit's beams).
    subprocess.run(
        [cli, "-q", "run", str(scan), "-c", str(config), "--sensor", "hdl64e", "-o", str(out)],
        check=True,
    )
    (fates_csv,) = out.rglob("frame_00000.fate.csv")
    written = np.fromfile(fates_csv.with_name("frame_00000.bin"), "<f4").reshape(-1, 4)
    rows = read_fates(fates_csv)

    applied = ln.Chain.from_toml(config, sensor="hdl64e").apply(pts, intensity_scale="unit")
    n = len(pts)
    # run writes the returns the sensor reports: recorded points in input order (their
    # index in `point`), then the added echoes (-1), as apply orders its rows.
    kept = applied[applied["kept"]]
    assert len(rows) == len(written) == len(kept)
    point = np.array([int(r["point"]) for r in rows])
    assert np.array_equal(point, np.where(np.arange(len(applied)) < n, np.arange(len(applied)), -1)[applied["kept"]])
    assert np.array_equal(np.array([int(r["fate"]) for r in rows]), kept["fate"])
    assert np.array_equal(np.array([int(r["cause"]) for r in rows]), kept["cause"])
    clean = np.array([float(r["range_clean"]) for r in rows], np.float32)
    assert np.array_equal(clean, kept["range_clean"])
    for i, name in enumerate("xyz"):
        assert np.array_equal(written[:, i], kept[name]), name
    assert np.allclose(written[:, 3] * 255, kept["intensity"], atol=1e-3)
    # The case is the one meant: echoes on lasers past 31, and exactly laser 40 occluded.
    added = kept[kept["fate"] == ln.FATES.index("added")]
    assert len(added) > 100 and (added["laser"] > 31).any()
    occluded = applied["fate"][:n] == ln.FATES.index("occluded")
    assert (occluded == (laser == 40)).all()
