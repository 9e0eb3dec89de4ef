#!/usr/bin/env python3
"""Cross-check of the VLP-32C, HDL-64E S2/S3 and VLS-128 decoders (src/sensor/) with velodyne_decoder.

No public capture of these models was reachable (see /work/notes/h-sens.md), so this
script synthesizes captures from the packet layouts of the manuals: 40 data packets per
case, seeded random distances (about 10 % zero) and intensities, block azimuths advancing
by a whole number of centidegrees per firing (about 10 Hz) and crossing 360 degrees,
device timestamps one packet period apart:

  vlp32c_single, vlp32c_dual        VLP-32C, mode byte 0x37 / 0x39, product byte 0x28
  hdl64e_s2_single, hdl64e_s2_dual  HDL-64E S2: blocks alternate 0xFFEE / 0xFFDD, no mode
  hdl64e_s3_single, hdl64e_s3_dual  or product byte (status bytes), dual = strongest
                                    upper, strongest lower, last upper, last lower
  vls128_single, vls128_dual        VLS-128 (firmware 5.2.3+, 2.89 us channel): blocks
  vls128_fw51_single, _dual         flagged 0xFFEE, 0xFFDD, 0xFFCC, 0xFFBB in turn (dual:
                                    one firing in blocks 0-7, last and strongest of each
                                    bank adjacent, blocks 8-11 empty), product byte 0xA1;
                                    fw5.1: 8/3 us channel (velodyne_decoder tells the two
                                    apart by the packet spacing, as src/sensor/ does)

velodyne_decoder (pip) decodes each case with the model set explicitly and the angles of
its bundled calibration (VLP-32C.yml: the VLP-32C manual's table; HDL-64E_S3-VeloView.yml:
VeloView's default HDL-64.xml), reduced to rot_correction and vert_correction so that its
plain (not "advanced") path runs, as src/sensor/ has no distance corrections. Each case
is written to DIR as NAME.bin (the 1206-byte payloads, concatenated) and NAME.csv (x, y,
z, intensity, time in seconds past the hour, ring, return type: 1 strongest, 2 last, 3
both), and the ignored test `synthesized_captures_match_velodyne_decoder` of
tests/integration/sensor_models.rs decodes NAME.bin with the model named in DIR/manifest.txt and
matches every point. Two more cases give both decoders a unit's full calibration file
(hdl64e_s3_calibrated: HDL-64E_S3-VeloView.yml; hdl64e_s2_calibrated_dual: the SZTAKI
S2 file), read by src/sensor/calibration.rs; their intensities are not compared
(velodyne_decoder applies the focal intensity correction, lidar-noise keeps the byte).

Real captures (`--captures FOLDER`): every classic pcap in FOLDER whose data packets
are a VLP-32C's (product byte 0x28) or a VLS-128's (0xA1) is a case too, named
real_<file stem>, its first 300 data packets decoded by both sides as above (model set
from the product byte; for the VLS-128 the firmware timing nearest the packet spacing),
and marked `real` in the manifest (the test's tolerances for real data). None is in the repository; the manual names the
public ones checked and where they come from.

usage: sensor_models_check.py [DIR] [--captures FOLDER]
       (run from the project root; DIR default /tmp/sensor_models_check)
"""

import os
import pathlib
import subprocess
import sys

import numpy as np
import velodyne_decoder as vd
import yaml

root = pathlib.Path(__file__).resolve().parents[2]
args = sys.argv[1:]
captures = None
if "--captures" in args:
    k = args.index("--captures")
    captures = pathlib.Path(args[k + 1])
    del args[k : k + 2]
out = pathlib.Path(args[0] if args else "/tmp/sensor_models_check")
out.mkdir(parents=True, exist_ok=True)
calib_dir = pathlib.Path(vd.__file__).parent / "calibrations"


def angles_only(name, resolution):
    """velodyne_decoder's bundled calibration reduced to its two angles per laser."""
    data = yaml.safe_load((calib_dir / name).read_text())
    lasers = [
        {"laser_id": l["laser_id"], "rot_correction": l["rot_correction"], "vert_correction": l["vert_correction"]}
        for l in data["lasers"]
    ]
    text = yaml.dump({"distance_resolution": resolution, "num_lasers": len(lasers), "lasers": lasers})
    return vd.Calibration.from_string(text)


# (case, model name in src/sensor/, vd model, calibration, firing us, centideg per firing,
#  banks, dual)
cal32 = angles_only("VLP-32C.yml", 0.004)
cal64 = angles_only("HDL-64E_S3-VeloView.yml", 0.002)
cal128 = angles_only("Alpha Prime.yml", 0.004)
cases = [
    ("vlp32c_single", "VLP-32C", vd.Model.VLP32C, cal32, 55.296, 20, 1, False),
    ("vlp32c_dual", "VLP-32C", vd.Model.VLP32C, cal32, 55.296, 20, 1, True),
    ("hdl64e_s2_single", "HDL-64E S2", vd.Model.HDL64E_S2, cal64, 48.0, 17, 2, False),
    ("hdl64e_s2_dual", "HDL-64E S2", vd.Model.HDL64E_S2, cal64, 48.0, 17, 2, True),
    ("hdl64e_s3_single", "HDL-64E S3", vd.Model.HDL64E_S3, cal64, 57.6, 21, 2, False),
    ("hdl64e_s3_dual", "HDL-64E S3", vd.Model.HDL64E_S3, cal64, 57.6, 21, 2, True),
    # A unit's full calibration (distance, two-point, vertical and horizontal offsets):
    # both decoders read the same ROS YAML file.
    ("hdl64e_s3_calibrated", "HDL-64E S3", vd.Model.HDL64E_S3, "HDL-64E_S3-VeloView.yml", 57.6, 21, 2, False),
    ("hdl64e_s2_calibrated_dual", "HDL-64E S2", vd.Model.HDL64E_S2, "HDL-64E_S2.1-sztaki.yml", 48.0, 17, 2, True),
    # VLS-128 (Alpha Prime), both firmware timings, angles of the bundled Alpha Prime.yml.
    ("vls128_single", "VLS-128", vd.Model.VLS128, cal128, 57.8, 21, 4, False),
    ("vls128_dual", "VLS-128", vd.Model.VLS128, cal128, 57.8, 21, 4, True),
    ("vls128_fw51_single", "VLS-128 fw5.1", vd.Model.VLS128, cal128, 160 / 3, 19, 4, False),
    ("vls128_fw51_dual", "VLS-128 fw5.1", vd.Model.VLS128, cal128, 160 / 3, 19, 4, True),
]

HOUR0 = 7200  # host clock at a whole hour, small so float64 seconds keep nanoseconds


def decode_and_write(name, model, cal, payloads, skip_first_columns):
    """Decodes `payloads` with velodyne_decoder (`model`, calibration `cal`) and writes
    NAME.bin (the payloads) and NAME.csv (its points) into `out`; leaves out the points
    of columns below `skip_first_columns` (0: none). Returns the number of points."""
    config = vd.Config(model=model, calibration=cal, min_range=0.0, max_range=1e4, timestamp_first_packet=True)
    packets = [
        vd.VelodynePacket(HOUR0 + int.from_bytes(p[1200:1204], "little") * 1e-6, np.frombuffer(p, dtype=np.uint8))
        for p in payloads
    ]
    stamp, points = vd.ScanDecoder(config).decode(packets, as_pcl_structs=True)
    base = stamp.device % 3600.0
    if skip_first_columns:
        points = points[points["column"] >= skip_first_columns]
    (out / f"{name}.bin").write_bytes(b"".join(payloads))
    with open(out / f"{name}.csv", "w") as f:
        f.write("x,y,z,intensity,time,ring,return_type\n")
        for q in points:
            f.write(
                "%.9g,%.9g,%.9g,%d,%.9f,%d,%d\n"
                % (q["x"], q["y"], q["z"], q["intensity"], base + float(q["time"]), q["ring"], q["return_type"])
            )
    return len(points)


rng = np.random.default_rng(31)
manifest = []
FLAGS = [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF]
for name, model_name, model, cal, firing_us, step, banks, dual in cases:
    per_firing = banks * (2 if dual else 1)
    firings = 12 // per_firing
    used = firings * per_firing  # the VLS-128 in dual mode leaves blocks 8-11 empty
    adjacent = banks == 4  # VLS-128 dual: last, strongest of one bank in adjacent blocks
    period = firings * firing_us
    payloads = []
    for i in range(40):
        p = bytearray(1206)
        for b in range(12):
            f = i * firings + min(b, used - 1) // per_firing
            az = (35_000 + f * step) % 36_000
            bank = (b // 2) % banks if dual and adjacent else b % banks
            flag = FLAGS[bank] if b < used else 0
            p[b * 100 : b * 100 + 2] = flag.to_bytes(2, "little")
            if b >= used:
                p[b * 100 + 2 : b * 100 + 4] = (az).to_bytes(2, "little")
                continue
            p[b * 100 + 2 : b * 100 + 4] = az.to_bytes(2, "little")
            for c in range(32):
                d = int(rng.integers(1, 10_000)) if rng.random() > 0.1 else 0
                o = b * 100 + 4 + 3 * c
                p[o : o + 2] = d.to_bytes(2, "little")
                p[o + 2] = int(rng.integers(0, 256))
        if dual:
            # Second return group of each firing: a distance that differs from the first
            # (velodyne_decoder merges equal pairs into one "both" point).
            group = 1 if adjacent else banks
            for b in range(used):
                if (b // group) % 2 == 1:
                    for c in range(32):
                        o = b * 100 + 4 + 3 * c
                        first = int.from_bytes(p[o - 100 * group : o - 100 * group + 2], "little")
                        if first != 0 and p[o : o + 2] != b"\0\0":
                            d = first + 1 + (c * 37 + b) % 500
                            p[o : o + 2] = d.to_bytes(2, "little")
        ts = int(round(1_000_000 + i * period))
        p[1200:1204] = ts.to_bytes(4, "little")
        if banks != 2:
            p[1204] = 0x39 if dual else 0x37
            p[1205] = 0x28 if banks == 1 else 0xA1
        else:
            p[1204] = 0x48 + i % 7  # status type and value: no meaning to the decoders
            p[1205] = (i * 13) % 256
        payloads.append(bytes(p))
    calib_file = ""
    if isinstance(cal, str):
        calib_file = str(calib_dir / cal)
        cal = vd.Calibration.read(calib_file)
    skip_first = banks == 4
    # velodyne_decoder's VLS-128 path interpolates nothing in the first packet (its
    # rotation rate comes from the packet before) and times it with the 2.89 us channel
    # before it has measured the packet spacing: its points are left out here (columns
    # 0-2 single, 0 dual) and the test leaves out packet 0's.
    n_points = decode_and_write(name, model, cal, payloads, (1 if dual else 3) if skip_first else 0)
    manifest.append(f"{name}\t{model_name}\t{calib_file}\t{'skip_first' if skip_first else ''}\n")
    print(f"velodyne_decoder {vd.__version__}: {name}: {n_points} points -> {out / name}.csv")


def pcap_payloads(path):
    """The 1206-byte UDP payloads of a classic pcap (Ethernet, IPv4 without options)."""
    data = path.read_bytes()
    if data[:4] not in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1"):
        return []
    payloads, off = [], 24
    while off + 16 <= len(data):
        incl = int.from_bytes(data[off + 8 : off + 12], "little")
        frame = data[off + 16 : off + 16 + incl]
        off += 16 + incl
        if len(frame) == 42 + 1206 and frame[42:44] == b"\xff\xee":
            payloads.append(frame[42:])
    return payloads


for path in sorted(captures.glob("*.pcap")) if captures else []:
    payloads = pcap_payloads(path)[:300]
    if len(payloads) < 3:
        continue
    product, mode = payloads[0][1205], payloads[0][1204]
    stamps = [int.from_bytes(p[1200:1204], "little") for p in payloads]
    spacing = float(np.median([b - a for a, b in zip(stamps, stamps[1:]) if 0 < b - a < 5000]))
    if product == 0x28:
        model_name, model, cal = "VLP-32C", vd.Model.VLP32C, cal32
    elif product == 0xA1:
        fw51 = abs(spacing - 160.0) < abs(spacing - 173.4)
        model_name, model, cal = ("VLS-128 fw5.1" if fw51 else "VLS-128"), vd.Model.VLS128, cal128
    else:
        print(f"{path}: product byte 0x{product:02x}: not a VLP-32C or VLS-128, left out")
        continue
    name = f"real_{path.stem}"
    skip_first = product == 0xA1
    n_points = decode_and_write(name, model, cal, payloads, (1 if mode == 0x39 else 3) if skip_first else 0)
    manifest.append(f"{name}\t{model_name}\t\t{'real skip_first' if skip_first else 'real'}\n")
    print(
        f"velodyne_decoder {vd.__version__}: {name} ({path.name}, {model_name}, mode 0x{mode:02x}, "
        f"packets {spacing:.0f} us apart): {n_points} points -> {out / name}.csv"
    )
(out / "manifest.txt").write_text("".join(manifest))

# HDL-64E S3 status-byte calibration: VeloView's S3 table written into the status bytes
# of 4,400 packets (each 16 packets: H M S D N Y G T V status, then W and six more types
# carrying 7 calibration bytes; the 1,820-byte block "UNIT#", noise thresholds, 64
# records of 28 bytes, a 21-byte tail ending in the CRC-16), starting mid-block;
# velodyne_decoder's hdl64e.read_status_info reads it back and its calibration is
# written as status_calib.yml; the Rust test reads the same packets' status bytes.
import struct

full = yaml.safe_load((calib_dir / "HDL-64E_S3-VeloView.yml").read_text())
records = b""
for l in sorted(full["lasers"], key=lambda l: l["laser_id"]):
    rec = struct.pack(
        "<BhhhhhhhhhBB",
        l["laser_id"],
        round(np.degrees(l["vert_correction"]) * 100),
        round(np.degrees(l["rot_correction"]) * 100),
        round(l.get("dist_correction", 0) * 1000),
        round(l.get("dist_correction_x", 0) * 1000),
        round(l.get("dist_correction_y", 0) * 1000),
        round(l.get("vert_offset_correction", 0) * 1000),
        round(l.get("horiz_offset_correction", 0) * 1000),
        round(l.get("focal_distance", 0) * 1000),
        round(l.get("focal_slope", 0) * 10),
        int(l.get("min_intensity", 0)),
        int(l.get("max_intensity", 255)),
    )
    # 7 more bytes a record: the last record's are read as the calibration date and
    # humidity (velodyne_decoder reads the last 28 bytes of the block as the tail).
    records += rec + bytes([16, 11, 15, 12, 47, 47, 25])
crc = vd.hdl64e.crc16(b"".join(records[i + 1 : i + 21] for i in range(0, len(records), 28)))
tail = struct.pack("<hHH", 600, 0, 36000) + bytes(13) + struct.pack("<H", crc)
block = b"UNIT#" + bytes([24, 24]) + records + tail
assert len(block) == 1820
data = (block[600:] + block + block)  # starts mid-block, as a capture does
status = {"H": 7, "M": 8, "S": 9, "D": 6, "N": 5, "Y": 24, "G": 0, "T": 20, "V": 227}
payloads = []
k = 0
for i in range(4400):
    p = bytearray(1206)
    for b in range(12):
        p[b * 100 : b * 100 + 2] = (0xEEFF if b % 2 == 0 else 0xDDFF).to_bytes(2, "little")
    p[1200:1204] = (1_000_000 + round(i * 345.6)).to_bytes(4, "little")
    phase = i % 16
    if phase < 9:
        t = "HMSDNYGTV"[phase]
        p[1204], p[1205] = ord(t), status[t]
    else:
        p[1204], p[1205] = ord("W1234567"[phase - 9]), data[k]
        k += 1
    payloads.append(bytes(p))
meta = vd.hdl64e.read_status_info(payloads)
calib = vd.hdl64e.status_info_to_calib_dict(meta)
calib.pop("status")
(out / "status_calib.yml").write_text(yaml.dump(calib, sort_keys=False))
(out / "hdl64e_s3_status.bin").write_bytes(b"".join(payloads))
print(f"velodyne_decoder hdl64e.read_status_info: {meta['Model']}, {len(meta['Calibration'])} lasers -> {out / 'status_calib.yml'}")
env = dict(os.environ, SENSOR_CHECK_DIR=str(out))
cmd = ["cargo", "test", "--test", "integration", "--", "--ignored", "--nocapture",
       "sensor_models::synthesized_captures_match_velodyne_decoder",
       "sensor_models::status_byte_calibration_matches_velodyne_decoder"]
sys.exit(subprocess.run(cmd, cwd=root, env=env).returncode)
