"""Shared helpers of the lidar_noise tests: where the repository, the command-line tool
and the shared data are, and a reader of the binary PLY files `lidar-noise run` writes
(written here from the PLY header's own description, not with the package)."""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "fixtures"
CONFIGS = sorted((REPO / "configs").glob("*.toml"))
SHARED_CAPTURE = REPO.parent / "shared" / "data" / "hdl32e" / "monterey.pcap"

_PLY_TYPES = {
    "char": "i1",
    "uchar": "u1",
    "short": "<i2",
    "ushort": "<u2",
    "int": "<i4",
    "uint": "<u4",
    "float": "<f4",
    "double": "<f8",
}


def read_ply(path):
    """The vertex table of a binary little-endian PLY file as a structured array."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in header, header[:3]
    fields, count = [], None
    for line in header:
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            count = int(parts[2])
        elif parts and parts[0] == "property":
            fields.append((parts[2], _PLY_TYPES[parts[1]]))
    return np.frombuffer(data, dtype=np.dtype(fields), count=count, offset=end)


def find_cli():
    """The lidar-noise binary: $LIDAR_NOISE_BIN, else the repository's debug or release
    build, else the PATH."""
    env = os.environ.get("LIDAR_NOISE_BIN")
    if env:
        return env
    for profile in ("debug", "release"):
        p = REPO / "target" / profile / "lidar-noise"
        if p.exists():
            return str(p)
    return shutil.which("lidar-noise")


@pytest.fixture(scope="session")
def cli():
    path = find_cli()
    if path is None:
        pytest.skip(
            "SKIPPED: no lidar-noise binary (set LIDAR_NOISE_BIN or run `cargo build`)"
        )
    return path
