"""A PyTorch Dataset that corrupts KITTI or nuScenes lidar scans on the fly with
lidar_noise, one seed per item, so that every epoch, worker count and machine sees the
same corrupted scan for the same item (the random streams are keyed by seed and frame,
never by process or scheduling).

Install (torch is not a dependency of lidar_noise):
    pip install ./python            # lidar_noise, from a clone of this repository
    pip install torch               # https://pytorch.org/get-started/locally/

Run on a folder of scans:
    python examples/python/torch_dataset.py /data/kitti/sequences/00/velodyne configs/adverse-weather.toml
    python examples/python/torch_dataset.py /data/nuscenes/samples/LIDAR_TOP configs/rain.toml --rotation-hz 20

KITTI was recorded with an HDL-64E (S2): KITTI points are placed on its 64 beams by
elevation (the chain is built for sensor "hdl64e-kitti", as `run` does); nuScenes' LIDAR_TOP is an HDL-32E at
20 Hz with rings. `--sensor NAME` says otherwise (the names of `lidar-noise run --sensor`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import lidar_noise as ln

try:
    import torch
    from torch.utils.data import DataLoader, Dataset
except ImportError:  # the class below still works as a plain sequence without torch
    torch = None
    Dataset = object  # type: ignore[misc,assignment]


class CorruptedScans(Dataset):
    """Scans of a folder (``*.bin`` KITTI or ``*.pcd.bin`` nuScenes) through a noise chain.

    Item ``i`` is corrupted with seed ``base_seed`` and frame ``i``: reproducible per
    item, independent between items, and the same in any DataLoader worker."""

    def __init__(self, folder, config, base_seed=0, rotation_hz=10.0, keep_dropped=False, sensor=None):
        self.files = sorted(Path(folder).glob("*.bin"))
        if not self.files:
            raise FileNotFoundError(f"{folder}: no .bin scans")
        if sensor is None:
            # The sensors the datasets were recorded with: nuScenes an HDL-32E, KITTI an
            # HDL-64E (S2).
            sensor = "hdl32e" if self.files[0].name.endswith(".pcd.bin") else "hdl64e-kitti"
        self.chain = ln.Chain.from_toml(config, sensor=sensor)
        self.base_seed = base_seed
        self.rotation_hz = rotation_hz
        self.keep_dropped = keep_dropped

    def __len__(self):
        return len(self.files)

    def __getitem__(self, i):
        (frame,) = ln.read(self.files[i])
        out = self.chain.apply(
            frame.points,
            seed=self.base_seed,
            frame=i,
            rotation_hz=self.rotation_hz,
            intensity_scale=frame.intensity_scale if frame.intensity_scale != "unstated" else "byte",
        )
        if not self.keep_dropped:
            out = out[out["kept"]]
        # x y z intensity (0-1) as the detectors' loaders expect, plus the fate code.
        cloud = np.stack(
            [out["x"], out["y"], out["z"], out["intensity"] / np.float32(255.0)], axis=1
        ).astype(np.float32)
        fate = out["fate"].astype(np.int64)
        if torch is not None:
            return torch.from_numpy(cloud), torch.from_numpy(fate)
        return cloud, fate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder")
    ap.add_argument("config")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rotation-hz", type=float, default=10.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sensor", default=None, help="sensor name (default: hdl64e for KITTI, hdl32e for nuScenes)")
    args = ap.parse_args(argv)
    data = CorruptedScans(args.folder, args.config, args.seed, args.rotation_hz, sensor=args.sensor)
    if torch is None:
        print("torch is not installed (pip install torch); iterating without a DataLoader", file=sys.stderr)
        items = (data[i] for i in range(min(len(data), 4)))
    else:
        loader = DataLoader(data, batch_size=None, num_workers=args.workers)
        items = (x for _, x in zip(range(4), loader))
    for i, (cloud, fate) in enumerate(items):
        print(f"scan {i}: {len(cloud)} points, {int((fate == 4).sum())} replaced, {int((fate == 5).sum())} added")


if __name__ == "__main__":
    main()
