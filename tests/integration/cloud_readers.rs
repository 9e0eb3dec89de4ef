//! The point-cloud readers (src/cloud/) on files built here from the documented layouts:
//! KITTI `.bin` (4 float32 LE), nuScenes `.pcd.bin` (5 float32 LE), PCD 0.7 (ascii, binary,
//! binary_compressed), CSV with a header. Exact round trips of known values, hand-written
//! bytes that fail on a wrong offset or byte order, and every bad input named by file and
//! place.

use lidar_noise::cloud::{
    self, detect, read_file, CloudPoint, Fields, Format, IntensityScale, ReadOptions,
};
use std::path::{Path, PathBuf};

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn read(path: &Path) -> cloud::Cloud {
    read_file(path, &ReadOptions::default()).unwrap()
}

fn err(path: &Path, options: ReadOptions) -> String {
    let e = read_file(path, &options).unwrap_err().to_string();
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    assert!(e.contains(&name), "error does not name the file: {e}");
    e
}

fn pt(x: f32, y: f32, z: f32, intensity: f32, ring: Option<u16>, time: Option<f64>) -> CloudPoint {
    CloudPoint {
        x,
        y,
        z,
        intensity,
        ring,
        time,
    }
}

fn le(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Known points with distinct values in every field (a field read at another offset, or
/// in the other byte order, gives another number).
fn known() -> Vec<CloudPoint> {
    vec![
        pt(1.5, -2.25, 0.125, 0.75, Some(3), Some(0.5)),
        pt(-40.0, 12.5, -1.75, 0.0, Some(0), Some(1.25)),
        pt(80.25, 0.0625, 3.0, 1.0, Some(31), Some(2.0)),
    ]
}

#[test]
fn kitti_round_trip_exact() {
    let dir = tempfile::tempdir().unwrap();
    let pts = known();
    let bytes = le(&pts
        .iter()
        .flat_map(|p| [p.x, p.y, p.z, p.intensity])
        .collect::<Vec<_>>());
    let path = write(dir.path(), "000000.bin", &bytes);
    let c = read(&path);
    assert_eq!(c.info.format, Format::Kitti);
    assert_eq!(c.info.points, 3);
    assert_eq!(c.info.intensity_scale, IntensityScale::Unit);
    assert_eq!(
        c.info.fields,
        Fields {
            intensity: true,
            ring: false,
            time: false
        }
    );
    for (got, want) in c.points.iter().zip(&pts) {
        assert_eq!(*got, pt(want.x, want.y, want.z, want.intensity, None, None));
    }
}

#[test]
fn kitti_offsets_and_byte_order_from_hand_written_bytes() {
    // 1.5f32 = 0x3fc00000, -2.0 = 0xc0000000, 0.25 = 0x3e800000, 0.5 = 0x3f000000, stored
    // little-endian: written out by hand, not through to_le_bytes.
    let bytes = [
        0x00, 0x00, 0xc0, 0x3f, 0x00, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x80, 0x3e, 0x00, 0x00, 0x00,
        0x3f,
    ];
    let dir = tempfile::tempdir().unwrap();
    let c = read(&write(dir.path(), "a.bin", &bytes));
    assert_eq!(c.points, vec![pt(1.5, -2.0, 0.25, 0.5, None, None)]);
}

#[test]
fn nuscenes_round_trip_and_hand_written_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let pts = known();
    let bytes = le(&pts
        .iter()
        .map(|p| [p.x, p.y, p.z, p.intensity * 255.0, p.ring.unwrap() as f32])
        .flat_map(|a| a.into_iter())
        .collect::<Vec<_>>());
    let path = write(dir.path(), "n008__LIDAR_TOP__1.pcd.bin", &bytes);
    let c = read(&path);
    assert_eq!(c.info.format, Format::NuScenes);
    assert_eq!(c.info.intensity_scale, IntensityScale::Byte);
    assert!(c.info.fields.ring && c.info.fields.intensity && !c.info.fields.time);
    for (got, want) in c.points.iter().zip(&pts) {
        let w = pt(
            want.x,
            want.y,
            want.z,
            want.intensity * 255.0,
            want.ring,
            None,
        );
        assert_eq!(*got, w);
    }
    // x 1.5, y -2, z 0.25, intensity 100 (0x42c80000), ring 17 (0x41880000), little-endian.
    let hand = [
        0x00, 0x00, 0xc0, 0x3f, 0x00, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x80, 0x3e, 0x00, 0x00, 0xc8,
        0x42, 0x00, 0x00, 0x88, 0x41,
    ];
    let c = read(&write(dir.path(), "b.pcd.bin", &hand));
    assert_eq!(c.points, vec![pt(1.5, -2.0, 0.25, 100.0, Some(17), None)]);
}

#[test]
fn bin_size_not_a_multiple_names_size_and_remainder() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "cut.bin", &[0u8; 16 * 3 + 5]);
    let e = err(&path, ReadOptions::default());
    assert!(
        e.contains("53 bytes") && e.contains("5 bytes left over"),
        "{e}"
    );
    assert!(
        e.contains("3 whole points") && e.contains("byte offset 48"),
        "{e}"
    );
    // 40 bytes is two nuScenes points: the message says so.
    let path = write(dir.path(), "renamed.bin", &[0u8; 40]);
    let e = err(&path, ReadOptions::default());
    assert!(
        e.contains("8 bytes left over") && e.contains("nuScenes"),
        "{e}"
    );
    let path = write(dir.path(), "cut.pcd.bin", &[0u8; 20 * 2 + 4]);
    let e = err(&path, ReadOptions::default());
    assert!(
        e.contains("44 bytes") && e.contains("4 bytes left over"),
        "{e}"
    );
}

#[test]
fn non_finite_coordinates_name_the_point() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = vec![0.0f32; 4 * 4];
    v[2 * 4 + 1] = f32::NAN; // point 2, y
    let e = err(
        &write(dir.path(), "nan.bin", &le(&v)),
        ReadOptions::default(),
    );
    assert!(e.contains("point 2 ") && e.contains("y is NaN"), "{e}");
    // The first offending point is named, whichever value it is (a KITTI scan is checked
    // as it is parsed).
    let mut v = vec![0.0f32; 4 * 6];
    v[3 * 4 + 3] = f32::NEG_INFINITY; // point 3, intensity
    v[5 * 4] = f32::NAN; // point 5, x
    let e = err(
        &write(dir.path(), "last.bin", &le(&v)),
        ReadOptions::default(),
    );
    assert!(
        e.contains("last.bin") && e.contains("point 3 ") && e.contains("intensity is -inf"),
        "{e}"
    );
    let mut v = vec![0.0f32; 5 * 2];
    v[5 + 2] = f32::INFINITY; // point 1, z
    let e = err(
        &write(dir.path(), "inf.pcd.bin", &le(&v)),
        ReadOptions::default(),
    );
    assert!(e.contains("point 1 ") && e.contains("z is inf"), "{e}");
}

#[test]
fn ring_out_of_range_for_the_lasers_given() {
    let dir = tempfile::tempdir().unwrap();
    let v = [0.0, 1.0, 0.0, 5.0, 31.0, 0.0, 1.0, 0.0, 5.0, 32.0];
    let path = write(dir.path(), "r.pcd.bin", &le(&v));
    // Without a sensor the ring is only checked to be a whole number.
    assert_eq!(read(&path).points[1].ring, Some(32));
    let options = ReadOptions {
        lasers: Some(32),
        ..Default::default()
    };
    let e = err(&path, options);
    assert!(
        e.contains("point 1 ") && e.contains("ring 32") && e.contains("32 lasers"),
        "{e}"
    );
    // A fractional or negative ring is refused whatever the sensor.
    let path = write(dir.path(), "f.pcd.bin", &le(&[0.0, 1.0, 0.0, 5.0, 2.5]));
    assert!(err(&path, ReadOptions::default()).contains("ring 2.5"));
    let path = write(dir.path(), "g.pcd.bin", &le(&[0.0, 1.0, 0.0, 5.0, -1.0]));
    assert!(err(&path, ReadOptions::default()).contains("ring -1"));
}

/// A PCD field for the tests: name, SIZE, TYPE, COUNT.
type PcdField<'a> = (&'a str, usize, char, usize);

/// A PCD header for `fields` (name, size, type, count) and `n` points.
fn pcd_header(fields: &[PcdField], n: usize, data: &str) -> String {
    let col = |f: &dyn Fn(&PcdField) -> String| fields.iter().map(f).collect::<Vec<_>>().join(" ");
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {}\nSIZE {}\nTYPE {}\n\
         COUNT {}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n",
        col(&|f| f.0.to_string()),
        col(&|f| f.1.to_string()),
        col(&|f| f.2.to_string()),
        col(&|f| f.3.to_string()),
    )
}

/// Fields of the PCD tests: x y z F4, an unknown 3-float field between them and the rest
/// (skipped), intensity U1, ring U2, a 1-byte pad, time F8. Intensity as a byte: known()
/// scaled to 0-255.
const PCD_FIELDS: [PcdField; 7] = [
    ("x", 4, 'F', 1),
    ("y", 4, 'F', 1),
    ("z", 4, 'F', 1),
    ("normal", 4, 'F', 3),
    ("intensity", 1, 'U', 1),
    ("ring", 2, 'U', 1),
    ("timestamp", 8, 'F', 1),
];

fn pcd_expected() -> Vec<CloudPoint> {
    known()
        .into_iter()
        .map(|p| CloudPoint {
            intensity: (p.intensity * 200.0).round(),
            ..p
        })
        .collect()
}

/// Each point's fields as stored, one byte vector per field (normals 9, 8, 7).
fn pcd_field_bytes(p: &CloudPoint) -> Vec<Vec<u8>> {
    vec![
        p.x.to_le_bytes().to_vec(),
        p.y.to_le_bytes().to_vec(),
        p.z.to_le_bytes().to_vec(),
        le(&[9.0, 8.0, 7.0]),
        vec![p.intensity as u8],
        p.ring.unwrap().to_le_bytes().to_vec(),
        p.time.unwrap().to_le_bytes().to_vec(),
    ]
}

fn pcd_binary(pts: &[CloudPoint]) -> Vec<u8> {
    let mut out = pcd_header(&PCD_FIELDS, pts.len(), "binary").into_bytes();
    for p in pts {
        out.extend(pcd_field_bytes(p).concat());
    }
    out
}

fn pcd_compressed(pts: &[CloudPoint]) -> Vec<u8> {
    // One block per field: all x, then all y, ... (PCL pcd_io.cpp).
    let mut raw = Vec::new();
    for f in 0..PCD_FIELDS.len() {
        for p in pts {
            raw.extend(&pcd_field_bytes(p)[f]);
        }
    }
    let packed = lzf::compress(&raw).unwrap();
    let mut out = pcd_header(&PCD_FIELDS, pts.len(), "binary_compressed").into_bytes();
    out.extend((packed.len() as u32).to_le_bytes());
    out.extend((raw.len() as u32).to_le_bytes());
    out.extend(packed);
    out
}

fn pcd_ascii(pts: &[CloudPoint]) -> Vec<u8> {
    let mut out = pcd_header(&PCD_FIELDS, pts.len(), "ascii");
    for p in pts {
        out += &format!(
            "{} {} {} 9 8 7 {} {} {}\n",
            p.x,
            p.y,
            p.z,
            p.intensity,
            p.ring.unwrap(),
            p.time.unwrap()
        );
    }
    out.into_bytes()
}

#[test]
fn pcd_round_trips_in_all_three_encodings() {
    let dir = tempfile::tempdir().unwrap();
    // Repeat the points so LZF finds back references.
    let pts: Vec<CloudPoint> = (0..40).flat_map(|_| pcd_expected()).collect();
    for (name, bytes) in [
        ("a.pcd", pcd_ascii(&pts)),
        ("b.pcd", pcd_binary(&pts)),
        ("c.pcd", pcd_compressed(&pts)),
    ] {
        let c = read(&write(dir.path(), name, &bytes));
        assert_eq!(c.info.format, Format::Pcd, "{name}");
        assert_eq!(c.info.intensity_scale, IntensityScale::Unstated);
        assert_eq!(
            c.info.fields,
            Fields {
                intensity: true,
                ring: true,
                time: true
            }
        );
        assert_eq!(c.points, pts, "{name}");
    }
}

#[test]
fn pcd_compressed_is_read_field_by_field() {
    // The same raw bytes laid out point by point (binary's layout) must not read the same.
    let dir = tempfile::tempdir().unwrap();
    let pts = pcd_expected();
    let aos: Vec<u8> = pts
        .iter()
        .flat_map(|p| pcd_field_bytes(p).concat())
        .collect();
    let packed = lzf::compress(&aos).unwrap();
    let mut bytes = pcd_header(&PCD_FIELDS, pts.len(), "binary_compressed").into_bytes();
    bytes.extend((packed.len() as u32).to_le_bytes());
    bytes.extend((aos.len() as u32).to_le_bytes());
    bytes.extend(packed);
    let got = read_file(
        &write(dir.path(), "aos.pcd", &bytes),
        &ReadOptions::default(),
    );
    assert!(got.map_or(true, |c| c.points != pts));
}

#[test]
fn pcd_types_signed_and_double() {
    // x y z as F8, intensity F4, ring I1, t I4 (negative): sign extension and widths.
    let fields = [
        ("x", 8, 'F', 1),
        ("y", 8, 'F', 1),
        ("z", 8, 'F', 1),
        ("i", 4, 'F', 1),
        ("ring", 1, 'I', 1),
        ("t", 4, 'I', 1),
    ];
    let mut bytes = pcd_header(&fields, 1, "binary").into_bytes();
    bytes.extend(0.1f64.to_le_bytes());
    bytes.extend((-7.5f64).to_le_bytes());
    bytes.extend(1e3f64.to_le_bytes());
    bytes.extend(42.5f32.to_le_bytes());
    bytes.push(5);
    bytes.extend((-123456i32).to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let c = read(&write(dir.path(), "t.pcd", &bytes));
    assert_eq!(
        c.points,
        vec![pt(
            0.1f64 as f32,
            -7.5,
            1000.0,
            42.5,
            Some(5),
            Some(-123456.0)
        )]
    );
}

#[test]
fn pcd_hand_written_binary_offsets() {
    // FIELDS x y z rgb intensity; rgb is skipped; intensity follows it at byte 16.
    let head = "VERSION .7\nFIELDS x y z rgb intensity\nSIZE 4 4 4 4 4\nTYPE F F F U F\n\
                WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n";
    let mut bytes = head.as_bytes().to_vec();
    bytes.extend([
        0x00, 0x00, 0xc0, 0x3f, // x 1.5
        0x00, 0x00, 0x00, 0xc0, // y -2
        0x00, 0x00, 0x80, 0x3e, // z 0.25
        0xff, 0xff, 0xff, 0xff, // rgb
        0x00, 0x00, 0xc8, 0x42, // intensity 100
    ]);
    let dir = tempfile::tempdir().unwrap();
    let c = read(&write(dir.path(), "h.pcd", &bytes));
    assert_eq!(c.points, vec![pt(1.5, -2.0, 0.25, 100.0, None, None)]);
    assert_eq!(
        c.info.fields,
        Fields {
            intensity: true,
            ring: false,
            time: false
        }
    );
}

#[test]
fn pcd_bad_headers_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let pts = pcd_expected();
    // A required field missing.
    let no_z = pcd_header(&[("x", 4, 'F', 1), ("y", 4, 'F', 1)], 1, "ascii") + "1 2\n";
    let e = err(
        &write(dir.path(), "noz.pcd", no_z.as_bytes()),
        ReadOptions::default(),
    );
    assert!(e.contains("required field z is missing"), "{e}");
    // Binary data one byte short of the header's claim.
    let mut short = pcd_binary(&pts);
    short.pop();
    let e = err(
        &write(dir.path(), "short.pcd", &short),
        ReadOptions::default(),
    );
    assert!(
        e.contains("3 points of 35 bytes") && e.contains("104 bytes after"),
        "{e}"
    );
    // 2^40 points claimed: refused by the data size, not allocated.
    for data in ["binary", "ascii", "binary_compressed"] {
        let huge = pcd_header(&PCD_FIELDS, 1 << 40, data);
        let mut bytes = huge.into_bytes();
        if data == "ascii" {
            bytes.extend(b"1 2 3 9 8 7 1 2 3\n");
        } else {
            bytes.extend([1u8; 35]);
        }
        let e = err(
            &write(dir.path(), "huge.pcd", &bytes),
            ReadOptions::default(),
        );
        assert!(e.contains("1099511627776"), "{data}: {e}");
    }
    // SIZE with the wrong number of entries, a bad type, a size a type cannot take.
    let bad = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 0\nDATA ascii\n";
    let e = err(
        &write(dir.path(), "s.pcd", bad.as_bytes()),
        ReadOptions::default(),
    );
    assert!(
        e.contains("line 3 (SIZE)") && e.contains("2 entries for 3"),
        "{e}"
    );
    let bad = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nPOINTS 0\nDATA ascii\n";
    let e = err(
        &write(dir.path(), "s3.pcd", bad.as_bytes()),
        ReadOptions::default(),
    );
    assert!(e.contains("field z has TYPE F with SIZE 3"), "{e}");
    // An ascii line with a value missing, and one that is not a number.
    let mut text = String::from_utf8(pcd_ascii(&pts)).unwrap();
    text = text.replacen(" 9 8 7 ", " 9 8 ", 1);
    let e = err(
        &write(dir.path(), "a.pcd", text.as_bytes()),
        ReadOptions::default(),
    );
    assert!(
        e.contains("line 12 (point 0)") && e.contains("8 values"),
        "{e}"
    );
    let text = String::from_utf8(pcd_ascii(&pts))
        .unwrap()
        .replace("-40 ", "-4o ");
    let e = err(
        &write(dir.path(), "b.pcd", text.as_bytes()),
        ReadOptions::default(),
    );
    assert!(
        e.contains("line 13 (point 1), field x") && e.contains("\"-4o\""),
        "{e}"
    );
    // Compressed data whose sizes disagree, or that is corrupt.
    let mut c = pcd_compressed(&pts);
    let at = c.len() - 1;
    c.truncate(at);
    let e = err(&write(dir.path(), "c.pcd", &c), ReadOptions::default());
    assert!(e.contains("compressed size"), "{e}");
    // NaN coordinates in ascii: named by point.
    let text = String::from_utf8(pcd_ascii(&pts))
        .unwrap()
        .replace("80.25 ", "nan ");
    let e = err(
        &write(dir.path(), "n.pcd", text.as_bytes()),
        ReadOptions::default(),
    );
    assert!(e.contains("point 2 ") && e.contains("x is NaN"), "{e}");
}

#[test]
fn csv_round_trip_with_aliases_and_delimiters() {
    let dir = tempfile::tempdir().unwrap();
    let pts = known();
    for (name, sep, head) in [
        ("a.csv", ",", "X,Y,Z,Intensity,Ring,Timestamp,label"),
        ("b.csv", ";", "label;timestamp;z;y;x;reflectance;ring_index"),
        ("c.txt", " ", "//X Y Z t i ring"),
    ] {
        let cols: Vec<String> = head.split(sep).map(|s| s.to_ascii_lowercase()).collect();
        let mut text = format!("{head}\n");
        for p in &pts {
            let row: Vec<String> = cols
                .iter()
                .map(|c| match c.trim_start_matches("//") {
                    "x" => p.x.to_string(),
                    "y" => p.y.to_string(),
                    "z" => p.z.to_string(),
                    "intensity" | "reflectance" | "i" => p.intensity.to_string(),
                    "ring" | "ring_index" => p.ring.unwrap().to_string(),
                    "timestamp" | "t" => p.time.unwrap().to_string(),
                    _ => "car".to_string(),
                })
                .collect();
            text += &row.join(sep);
            text += "\n";
        }
        let c = read(&write(dir.path(), name, text.as_bytes()));
        assert_eq!(c.info.format, Format::Csv, "{name}");
        assert_eq!(c.points, pts, "{name}");
    }
}

#[test]
fn csv_bad_rows_name_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let bad =
        |name: &str, bytes: &[u8]| err(&write(dir.path(), name, bytes), ReadOptions::default());
    let e = bad("m.csv", b"x,y,z,intensity\n1,2,3,4\n5,,7,8\n");
    assert!(
        e.contains("line 3, column 2 (y)") && e.contains("missing"),
        "{e}"
    );
    let e = bad("s.csv", b"x,y,z,intensity\n1,2,3,4\n5,6,7\n");
    assert!(e.contains("line 3, column 4 (intensity)"), "{e}");
    let e = bad("u.csv", b"x,y,z\n1,2,3\n4,5,6\n7,8,abc\n");
    assert!(
        e.contains("line 4, column 3 (z)") && e.contains("\"abc\""),
        "{e}"
    );
    let e = bad("h.csv", b"x,y,height\n1,2,3\n");
    assert!(e.contains("no z column"), "{e}");
    let e = bad("i.csv", b"x,y,z\n1,2,3\n1,inf,3\n");
    assert!(e.contains("point 1 ") && e.contains("y is inf"), "{e}");
}

#[test]
fn detection_by_extension_and_content() {
    let d = |name: &str, head: &[u8]| detect(Path::new(name), head).ok();
    assert_eq!(d("seq/velodyne/000001.bin", &[0; 16]), Some(Format::Kitti));
    assert_eq!(d("LIDAR_TOP/x.pcd.bin", &[0; 16]), Some(Format::NuScenes));
    assert_eq!(d("X.PCD.BIN", &[0; 16]), Some(Format::NuScenes));
    assert_eq!(d("cloud.pcd", b""), Some(Format::Pcd));
    assert_eq!(
        d("cloud.dat", b"# .PCD v0.7\nVERSION 0.7\n"),
        Some(Format::Pcd)
    );
    assert_eq!(
        d("points.txt", b"x y z intensity\n1 2 3 4\n"),
        Some(Format::Csv)
    );
    assert_eq!(d("points.csv", b""), Some(Format::Csv));
    assert_eq!(d("points.txt", b"hello\n"), None);
    // An explicit format overrides the name.
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "scan.dat", &le(&[1.0, 2.0, 3.0, 4.0, 5.0]));
    let options = ReadOptions {
        format: Some(Format::NuScenes),
        ..Default::default()
    };
    assert_eq!(read_file(&path, &options).unwrap().points[0].ring, Some(5));
    let e = err(&path, ReadOptions::default());
    assert!(e.contains("not a point-cloud format"), "{e}");
}

#[test]
fn missing_file_is_named() {
    let e = read_file(Path::new("/nonexistent/x.bin"), &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/x.bin"), "{e}");
}

#[test]
fn fuzz_corpus_files_read_whole() {
    // The seed corpus was written by a separate script (Python struct and its own LZF
    // encoder), so the compressed file checks the decoder against another encoder.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    let cases = [
        ("cloud-bin/000000.bin", 4),
        ("cloud-bin/n015__LIDAR_TOP__1.pcd.bin", 4),
        ("cloud-pcd/ascii.pcd", 4),
        ("cloud-pcd/binary.pcd", 12),
        ("cloud-pcd/compressed.pcd", 12),
        ("cloud-csv/points.csv", 4),
        ("cloud-csv/cloudcompare.txt", 4),
    ];
    for (rel, n) in cases {
        let c = read(&root.join(rel));
        assert_eq!(c.points.len(), n, "{rel}");
        assert_eq!(
            (c.points[2].x, c.points[2].y, c.points[2].z),
            (80.25, 0.0625, 3.0),
            "{rel}"
        );
    }
    let c = read(&root.join("cloud-pcd/compressed.pcd"));
    assert_eq!(c.points, read(&root.join("cloud-pcd/binary.pcd")).points);
    assert_eq!(c.points[10].ring, Some(31));
    assert_eq!(c.points[11].time, Some(3.0));
}
