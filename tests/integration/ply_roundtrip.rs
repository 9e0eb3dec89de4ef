//! Writes frames with `writers::ply`, reads them back with ply-rs-bw, and checks every
//! header line and value.

use lidar_noise::frame::{Return, ReturnKind};
use lidar_noise::writers::ply::{PlyColumns, PlyEncoding, PlyFrame};
use lidar_noise::writers::{write_file, Output};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Encoding, Ply, Property, PropertyType, ScalarType};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

const START: f64 = 1234.5;

/// A finite f32 drawn from all bit patterns, so exponents and signs of every kind appear.
fn any_f32(rng: &mut ChaCha8Rng) -> f32 {
    loop {
        let v = f32::from_bits(rng.random::<u32>());
        if v.is_finite() {
            return v;
        }
    }
}

fn synthetic_returns(n: usize, seed: u64) -> Vec<Return> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out: Vec<Return> = (0..n)
        .map(|i| Return {
            x: any_f32(&mut rng),
            y: rng.random_range(-120.0f32..120.0),
            z: any_f32(&mut rng),
            range: rng.random_range(0.0f32..130.0),
            azimuth: rng.random_range(0.0f32..360.0),
            elevation: rng.random_range(-31.0f32..11.0),
            time: START + i as f64 * 1.152e-6 + rng.random_range(0.0..1e-7),
            packet: (i / 384) as u32,
            raw_distance: rng.random(),
            intensity: rng.random(),
            laser: rng.random_range(0..32),
            ring: rng.random_range(0..32),
            block: rng.random_range(0..12),
            kind: ReturnKind::DualLast,
        })
        .collect();
    // Edge values worth seeing once: negative zero, tiny, extremes of the byte fields.
    if n >= 2 {
        out[0].x = -0.0;
        out[0].z = f32::MIN_POSITIVE;
        out[0].intensity = 255;
        out[1].x = f32::MAX;
        out[1].z = -f32::MAX;
        out[1].intensity = 0;
    }
    out
}

struct Extras {
    range_clean: Vec<f32>,
    power: Vec<f32>,
    fate: Vec<u8>,
    cause: Vec<u8>,
    ground: Vec<u8>,
    cluster: Vec<i32>,
}

fn extras(n: usize, seed: u64) -> Extras {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Extras {
        range_clean: (0..n).map(|_| any_f32(&mut rng)).collect(),
        power: (0..n).map(|_| rng.random_range(0.0f32..1e-6)).collect(),
        fate: (0..n).map(|_| rng.random()).collect(),
        cause: (0..n).map(|_| rng.random()).collect(),
        ground: (0..n).map(|_| rng.random_range(0..2)).collect(),
        cluster: (0..n)
            .map(|i| {
                if i == 0 {
                    i32::MIN
                } else {
                    rng.random_range(-1..5000)
                }
            })
            .collect(),
    }
}

fn read_back(bytes: &[u8]) -> Ply<DefaultElement> {
    Parser::<DefaultElement>::new()
        .read_ply(&mut &bytes[..])
        .expect("ply-rs-bw reads the file")
}

fn float(p: &Property) -> f32 {
    match p {
        Property::Float(v) => *v,
        other => panic!("expected float, got {other:?}"),
    }
}

fn uchar(p: &Property) -> u8 {
    match p {
        Property::UChar(v) => *v,
        other => panic!("expected uchar, got {other:?}"),
    }
}

fn int(p: &Property) -> i32 {
    match p {
        Property::Int(v) => *v,
        other => panic!("expected int, got {other:?}"),
    }
}

/// Bit-exact f32 comparison (so -0.0 and 0.0 differ).
fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits()
}

fn expected_properties(with_extras: bool) -> Vec<(&'static str, ScalarType)> {
    let mut v = vec![
        ("x", ScalarType::Float),
        ("y", ScalarType::Float),
        ("z", ScalarType::Float),
        ("intensity", ScalarType::UChar),
        ("ring", ScalarType::UChar),
        ("laser", ScalarType::UChar),
        ("azimuth", ScalarType::Float),
        ("range", ScalarType::Float),
        ("time", ScalarType::Float),
    ];
    if with_extras {
        v.extend([
            ("range_clean", ScalarType::Float),
            ("power", ScalarType::Float),
            ("fate", ScalarType::UChar),
            ("cause", ScalarType::UChar),
            ("ground", ScalarType::UChar),
            ("cluster", ScalarType::Int),
        ]);
    }
    v
}

fn check(encoding: PlyEncoding, with_extras: bool) {
    let n = 1000;
    let returns = synthetic_returns(n, 42);
    let ex = extras(n, 43);
    let comments = vec![
        "fate 0 = kept, 1 = lost to rain".to_string(),
        "seed 42".to_string(),
    ];
    let mut frame = PlyFrame::new(&returns, "/data/run 1.pcap", 17, START);
    frame.encoding = encoding;
    frame.comments = &comments;
    if with_extras {
        frame.columns = PlyColumns {
            range_clean: Some(&ex.range_clean),
            power: Some(&ex.power),
            fate: Some(&ex.fate),
            cause: Some(&ex.cause),
            ground: Some(&ex.ground),
            cluster: Some(&ex.cluster),
        };
    }
    let mut bytes = Vec::new();
    frame.write(&mut bytes).unwrap();
    let ply = read_back(&bytes);

    // Header.
    let want_encoding = match encoding {
        PlyEncoding::BinaryLittleEndian => Encoding::BinaryLittleEndian,
        PlyEncoding::Ascii => Encoding::Ascii,
    };
    assert_eq!(ply.header.encoding, want_encoding);
    assert_eq!(
        ply.header.comments[..3],
        [
            format!("lidar-noise {}", env!("CARGO_PKG_VERSION")),
            "source /data/run 1.pcap".to_string(),
            "frame 17".to_string(),
        ]
    );
    assert!(ply.header.comments.contains(&comments[0]));
    assert!(ply.header.comments.contains(&comments[1]));
    assert_eq!(ply.header.elements.len(), 1);
    let vertex = &ply.header.elements["vertex"];
    assert_eq!(vertex.count, n);
    let got: Vec<(String, PropertyType)> = vertex
        .properties
        .values()
        .map(|p| (p.name.clone(), p.data_type.clone()))
        .collect();
    let want: Vec<(String, PropertyType)> = expected_properties(with_extras)
        .into_iter()
        .map(|(name, ty)| (name.to_string(), PropertyType::Scalar(ty)))
        .collect();
    assert_eq!(got, want);

    // Payload.
    let points = &ply.payload["vertex"];
    assert_eq!(points.len(), n);
    for (i, (p, r)) in points.iter().zip(&returns).enumerate() {
        assert!(same(float(&p["x"]), r.x), "point {i} x");
        assert!(same(float(&p["y"]), r.y), "point {i} y");
        assert!(same(float(&p["z"]), r.z), "point {i} z");
        assert_eq!(uchar(&p["intensity"]), r.intensity, "point {i}");
        assert_eq!(uchar(&p["ring"]), r.ring, "point {i}");
        assert_eq!(uchar(&p["laser"]), r.laser, "point {i}");
        assert!(same(float(&p["azimuth"]), r.azimuth), "point {i} azimuth");
        assert!(same(float(&p["range"]), r.range), "point {i} range");
        let want_time = (r.time - START) as f32;
        assert!(same(float(&p["time"]), want_time), "point {i} time");
        assert!((f64::from(want_time) - (r.time - START)).abs() < 1e-9);
        if with_extras {
            assert!(
                same(float(&p["range_clean"]), ex.range_clean[i]),
                "point {i}"
            );
            assert!(same(float(&p["power"]), ex.power[i]), "point {i}");
            assert_eq!(uchar(&p["fate"]), ex.fate[i], "point {i}");
            assert_eq!(uchar(&p["cause"]), ex.cause[i], "point {i}");
            assert_eq!(uchar(&p["ground"]), ex.ground[i], "point {i}");
            assert_eq!(int(&p["cluster"]), ex.cluster[i], "point {i}");
        } else {
            assert_eq!(p.len(), 9, "no optional columns");
        }
    }
}

#[test]
fn binary_without_extras() {
    check(PlyEncoding::BinaryLittleEndian, false);
}

#[test]
fn binary_with_extras() {
    check(PlyEncoding::BinaryLittleEndian, true);
}

#[test]
fn ascii_without_extras() {
    check(PlyEncoding::Ascii, false);
}

#[test]
fn ascii_with_extras() {
    check(PlyEncoding::Ascii, true);
}

#[test]
fn only_some_extras_keep_their_relative_order() {
    let returns = synthetic_returns(5, 1);
    let ground = [1u8, 0, 1, 0, 1];
    let power = [0.25f32; 5];
    let mut frame = PlyFrame::new(&returns, "x.pcap", 0, START);
    frame.columns.ground = Some(&ground);
    frame.columns.power = Some(&power);
    let mut bytes = Vec::new();
    frame.write(&mut bytes).unwrap();
    let ply = read_back(&bytes);
    let names: Vec<&str> = ply.header.elements["vertex"]
        .properties
        .keys()
        .map(String::as_str)
        .collect();
    assert_eq!(&names[9..], ["power", "ground"]);
    assert_eq!(uchar(&ply.payload["vertex"][2]["ground"]), 1);
    assert_eq!(float(&ply.payload["vertex"][4]["power"]), 0.25);
}

#[test]
fn empty_frame_is_a_valid_file() {
    let frame = PlyFrame::new(&[], "x.pcap", 3, 0.0);
    let mut bytes = Vec::new();
    frame.write(&mut bytes).unwrap();
    let ply = read_back(&bytes);
    assert_eq!(ply.header.elements["vertex"].count, 0);
}

#[test]
fn written_through_write_file_and_protected_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("capture.pcap");
    std::fs::write(&input, b"not really a capture").unwrap();
    let returns = synthetic_returns(100, 9);
    let frame = PlyFrame::new(&returns, "capture.pcap", 2, START);
    assert_eq!(frame.extension(), "ply");

    let out = dir.path().join("frame_0002.ply");
    write_file(&frame, &out, &[input.as_path()]).unwrap();
    let bytes = std::fs::read(&out).unwrap();
    let ply = read_back(&bytes);
    assert_eq!(ply.payload["vertex"].len(), 100);
    assert!(same(float(&ply.payload["vertex"][99]["x"]), returns[99].x));

    let err = write_file(&frame, &input, &[Path::new(&input)]).unwrap_err();
    assert!(err.to_string().contains("refusing to overwrite"), "{err}");
    assert_eq!(std::fs::read(&input).unwrap(), b"not really a capture");
}
