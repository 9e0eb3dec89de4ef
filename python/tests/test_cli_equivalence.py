"""Chain.apply and Chain.detect give exactly what `lidar-noise run --keep-dropped` writes,
for every configuration in configs/ on every fixture capture (and on the shared capture's
first frames when ../shared exists): same positions, intensities, fates, causes, clean
ranges and powers, ground labels and cluster ids, bit for bit."""

import subprocess

import numpy as np
import pytest

import lidar_noise as ln
from conftest import CONFIGS, FIXTURES, SHARED_CAPTURE, read_ply

CAPTURES = sorted(FIXTURES.glob("*.pcap"))
# Columns of the PLY file compared, with the package's field of the same meaning.
COMPARED = [
    "x",
    "y",
    "z",
    "intensity",
    "ring",
    "laser",
    "azimuth",
    "range",
    "range_clean",
    "fate",
    "cause",
]


def cli_frames(cli, capture, config, out, frames=None):
    cmd = [cli, "-q", "run", str(capture), "-c", str(config), "--keep-dropped", "-o", str(out)]
    if frames is not None:
        cmd += ["--frames", frames]
    subprocess.run(cmd, check=True)
    folder = next(p for p in out.iterdir() if p.is_dir())
    return {int(p.stem.split("_")[1]): read_ply(p) for p in sorted(folder.glob("frame_*.ply"))}


def check_frame(chain, frame, ply, what):
    applied = chain.apply(frame.points, frame=frame.index)
    detected, _clusters = chain.detect(frame.points, frame=frame.index)
    assert len(applied) == len(ply), f"{what}: {len(applied)} rows, the CLI wrote {len(ply)}"
    for name in COMPARED:
        a, b = applied[name], ply[name]
        same = a.astype(b.dtype) == b
        assert same.all(), (
            f"{what}: field {name} differs at row {int(np.flatnonzero(~same)[0])} of {len(b)}: "
            f"{a[~same][:3]} vs the CLI's {b[~same][:3]}"
        )
        assert (detected[name] == a).all(), f"{what}: detect and apply differ in {name}"
    assert (applied["power"].astype(np.float32) == ply["power"]).all(), f"{what}: power"
    assert (detected["ground"].astype(np.uint8) == ply["ground"]).all(), f"{what}: ground"
    assert (detected["cluster"] == ply["cluster"]).all(), f"{what}: cluster"
    assert (applied["kept"] == np.isin(ply["fate"], [0, 4, 5])).all(), f"{what}: kept"


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
@pytest.mark.parametrize("capture", CAPTURES, ids=lambda p: p.stem)
def test_apply_matches_the_cli_on_the_fixtures(cli, tmp_path, capture, config):
    expected = cli_frames(cli, capture, config, tmp_path)
    frames = ln.read(capture)
    assert sorted(f.index for f in frames) == sorted(expected), "frames read vs written"
    chain = ln.Chain.from_toml(config)
    for frame in frames:
        check_frame(chain, frame, expected[frame.index], f"{capture.name} {config.name} frame {frame.index}")


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_apply_matches_the_cli_on_the_shared_capture(cli, tmp_path, config):
    if not SHARED_CAPTURE.exists():
        pytest.skip(f"SKIPPED: {SHARED_CAPTURE} is absent (../shared not mounted)")
    expected = cli_frames(cli, SHARED_CAPTURE, config, tmp_path, frames="1..2")
    frames = {f.index: f for f in ln.read(SHARED_CAPTURE) if f.index in expected}
    assert sorted(frames) == sorted(expected) == [1, 2]
    chain = ln.Chain.from_toml(str(config))
    for i, frame in frames.items():
        check_frame(chain, frame, expected[i], f"monterey {config.name} frame {i}")


# Configs whose per-laser options fit every sensor (the paper's and the p-diagram's name
# HDL-32E lasers past 15).
ANY_SENSOR = [c for c in CONFIGS if c.stem in ("clear", "rain", "adverse-weather", "pdiagram-sensor")]


@pytest.mark.parametrize("config", ANY_SENSOR, ids=lambda p: p.stem)
@pytest.mark.parametrize("sensor", ["vlp16", "vls128"])
def test_apply_matches_the_cli_on_captures_of_other_sensors(cli, tmp_path, sensor, config):
    # A capture of the sensor, synthesized by the CLI; read, its sensor is told by the
    # packets, and the chain built for it gives the CLI's fates, causes and ranges.
    subprocess.run(
        [cli, "-q", "synth", "--preset", "crossroad", "--sensor", sensor, "--rotations", "2",
         "-o", str(tmp_path / "synth")],
        check=True,
    )
    capture = tmp_path / "synth" / "crossroad.pcap"
    expected = cli_frames(cli, capture, config, tmp_path / "out")
    frames = ln.read(capture)
    assert frames and {f.sensor for f in frames} == {ln.Chain.from_toml("", sensor=sensor).sensor}
    assert sorted(f.index for f in frames) == sorted(expected)
    chain = ln.Chain.from_toml(config, sensor=frames[0].sensor)
    for frame in frames:
        check_frame(chain, frame, expected[frame.index], f"{sensor} {config.name} frame {frame.index}")
