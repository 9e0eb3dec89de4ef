#!/usr/bin/env python3
"""Writes the seed inputs of the `sensor` fuzz target (tests/integration/fuzz.rs) into
fuzz/corpus/sensor/, built from the documented 1206-byte data packet layout (VLP-16
manual 9.3.1 and HDL-32E manual: 12 blocks of 0xFFEE flag, azimuth u16 and 32 channels
of distance u16 + intensity u8; timestamp u32 at 1200; return mode at 1204; product id
at 1205; the VLP-32C's 0x28 packets the same; the HDL-64E's blocks alternate FF EE and
FF DD, bytes 1204-1205 are status bytes; the VLS-128's blocks are flagged FF EE, FF DD,
FF CC, FF BB by bank, three firings a packet, one in dual mode in blocks 0-7 with the
last and strongest return of a bank adjacent and blocks 8-11 empty, product id 0xA1):
no recorded data.

Input format: one option byte (bits 0-1: dual selection strongest/last/both; bit 2:
azimuth interpolation; bit 3: vertical offsets), then records of capture time (u64 LE,
nanoseconds), payload length (u16 LE) and the payload."""
import os
import struct

OUT = os.path.join(os.path.dirname(__file__), "..", "..", "fuzz", "corpus", "sensor")
MODES = {"strongest": 0x37, "last": 0x38, "dual": 0x39}
# Packet period (us) in single return mode and azimuth step per firing (centidegrees,
# 10 Hz) of each timing family: HDL-32E 12 firings of 46.08 us, VLP-16 family 12 blocks
# of 110.592 us.
FAMILY = {0x21: (552.96, 17), 0x22: (1327.104, 40), 0x24: (1327.104, 40), 0x28: (663.552, 20)}
# HDL-64E S2 and S3 (no mode or product byte; blocks alternate the upper bank's flag FF EE
# and the lower bank's FF DD, a pair per firing): firing period (us) and azimuth step per
# firing (centidegrees, 10 Hz), from the manuals' firing time tables as velodyne_decoder
# applies them.
FAMILY_64 = {"s2": (48.0, 17), "s3": (57.6, 21)}


def packets(product, mode, n, start_az=35500, options=0b0110):
    period, step = FAMILY[product]
    per = 2 if mode == "dual" else 1
    if per == 2:
        period /= 2
    out = bytearray([options])
    for i in range(n):
        p = bytearray(1206)
        for b in range(12):
            firing = i * (12 // per) + b // per
            az = (start_az + firing * step) % 36000
            p[b * 100:b * 100 + 4] = b"\xff\xee" + struct.pack("<H", az)
            for c in range(32):
                # Distances 2-60 m (2 mm units in both families), every seventh
                # channel empty; in dual mode the second block of a pair differs.
                d = 0 if (b * 32 + c) % 7 == 3 else 1000 + ((i * 389 + b * 97 + c * 31) % 29000)
                if per == 2 and b % 2 == 1:
                    d = d // 2
                at = b * 100 + 4 + c * 3
                p[at:at + 3] = struct.pack("<HB", d, (c * 13 + b * 5 + i) % 256)
        ts = 100_000 + int(i * period)
        p[1200:1206] = struct.pack("<IBB", ts, MODES[mode], product)
        out += struct.pack("<QH", (1_700_000_000_000_000 + int(i * period * 1000)), 1206) + p
    return bytes(out)


def packets_64(variant, mode, n, start_az=35000, options=0b0110):
    """HDL-64E packets: 6 firings (upper + lower block) a packet in single mode; in dual
    mode 3 firings of four blocks (strongest upper, lower, then last upper, lower), the
    four at one azimuth; bytes 1204-1205 are status bytes (type 'H', value)."""
    firing_us, step = FAMILY_64[variant]
    blocks_per_firing = 4 if mode == "dual" else 2
    firings = 12 // blocks_per_firing
    period = firings * firing_us
    out = bytearray([options])
    for i in range(n):
        p = bytearray(1206)
        for b in range(12):
            firing = i * firings + b // blocks_per_firing
            az = (start_az + firing * step) % 36000
            flag = b"\xff\xee" if b % 2 == 0 else b"\xff\xdd"
            p[b * 100:b * 100 + 4] = flag + struct.pack("<H", az)
            for c in range(32):
                d = 0 if (b * 32 + c) % 7 == 3 else 1000 + ((i * 389 + b * 97 + c * 31) % 29000)
                if mode == "dual" and b % 4 >= 2:
                    d = d // 2
                at = b * 100 + 4 + c * 3
                p[at:at + 3] = struct.pack("<HB", d, (c * 13 + b * 5 + i) % 256)
        ts = 100_000 + int(i * period)
        p[1200:1206] = struct.pack("<IBB", ts, ord("H"), i % 24)
        out += struct.pack("<QH", (1_700_000_000_000_000 + int(i * period * 1000)), 1206) + p
    return bytes(out)


# VLS-128 firing sequence (us) per firmware and azimuth step per firing (centidegrees,
# 10 Hz): 20 channels of 2.89 us (fw 5.2.3 and later) or 8/3 us (fw 5.1).
FAMILY_128 = {"fw523": (57.8, 21), "fw51": (160 / 3, 19)}
FLAGS_128 = [b"\xff\xee", b"\xff\xdd", b"\xff\xcc", b"\xff\xbb"]


def packets_128(variant, mode, n, start_az=35900, options=0b0110):
    """VLS-128 packets: 3 firings of 4 bank blocks, or in dual mode one firing of 4
    (last, strongest) block pairs and 4 empty blocks (no flag, zero slots)."""
    firing_us, step = FAMILY_128[variant]
    dual = mode == "dual"
    firings = 1 if dual else 3
    period = firings * firing_us
    out = bytearray([options])
    for i in range(n):
        p = bytearray(1206)
        for b in range(12):
            bank, firing = (b // 2, 0) if dual else (b % 4, b // 4)
            az = (start_az + (i * firings + firing) * step) % 36000
            if dual and b >= 8:
                p[b * 100 + 2:b * 100 + 4] = struct.pack("<H", az)
                continue
            p[b * 100:b * 100 + 4] = FLAGS_128[bank] + struct.pack("<H", az)
            for c in range(32):
                d = 0 if (b * 32 + c) % 7 == 3 else 1000 + ((i * 389 + b * 97 + c * 31) % 29000)
                if dual and b % 2 == 1:
                    d = d // 2
                at = b * 100 + 4 + c * 3
                p[at:at + 3] = struct.pack("<HB", d, (c * 13 + b * 5 + i) % 256)
        ts = 100_000 + int(round(i * period))
        p[1200:1206] = struct.pack("<IBB", ts, MODES[mode], 0xA1)
        out += struct.pack("<QH", (1_700_000_000_000_000 + int(i * period * 1000)), 1206) + p
    return bytes(out)


def main():
    os.makedirs(OUT, exist_ok=True)
    seeds = {
        "vlp16-strongest.bin": packets(0x22, "strongest", 4, options=0b0100),
        "vlp16-last.bin": packets(0x22, "last", 4, options=0b1100),
        "vlp16-dual.bin": packets(0x22, "dual", 4, options=0b0110),
        "puck-hi-res-dual-strongest.bin": packets(0x24, "dual", 4, options=0b0100),
        "hdl32e-strongest.bin": packets(0x21, "strongest", 4, options=0b0101),
        "vlp32c-strongest.bin": packets(0x28, "strongest", 4, options=0b0100),
        "vlp32c-dual.bin": packets(0x28, "dual", 4, options=0b0110),
        "hdl64e-s2-strongest.bin": packets_64("s2", "strongest", 4, options=0b0100),
        "hdl64e-s3-dual.bin": packets_64("s3", "dual", 4, options=0b0110),
        "vls128-strongest.bin": packets_128("fw523", "strongest", 4, options=0b0100),
        "vls128-dual.bin": packets_128("fw523", "dual", 6, options=0b0110),
        "vls128-fw51-last.bin": packets_128("fw51", "last", 4, options=0b0100),
        # An HDL-32E run followed by VLP-16 packets (issue 30 item 6: mixed sensors).
        "hdl32e-then-vlp16.bin": packets(0x21, "strongest", 3) + packets(0x22, "strongest", 3)[1:],
    }
    for name, data in seeds.items():
        with open(os.path.join(OUT, name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
