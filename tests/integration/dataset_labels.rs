//! Dataset ground-truth readers (src/cloud/labels.rs) on files built here from the
//! documented layouts: SemanticKITTI `.label` (uint32 LE, class low 16 bits, instance high),
//! nuScenes-lidarseg (uint8 class a point), nuScenes-panoptic (`.npz` with a uint16 array
//! class x 1000 + instance). No dataset file is committed (their licences are non-commercial).

use lidar_noise::cloud::labels::{parse, read_labels_file, LabelFormat};
use std::io::Write;
use std::path::Path;

fn kitti_bytes(values: &[(u16, u16)]) -> Vec<u8> {
    values
        .iter()
        .flat_map(|&(class, inst)| ((u32::from(inst) << 16) | u32::from(class)).to_le_bytes())
        .collect()
}

#[test]
fn semantic_kitti_classes_and_instances_map_to_ground_and_objects() {
    // road, car #5, car #6, building, moving-car #5 (another object), car without instance,
    // car #5 again, terrain.
    let values = [
        (40, 0),
        (10, 5),
        (10, 6),
        (50, 0),
        (252, 5),
        (10, 0),
        (10, 5),
        (72, 0),
    ];
    let bytes = kitti_bytes(&values);
    // The layout by hand: car #5 is 0x0005_000A, little-endian.
    assert_eq!(&bytes[4..8], &[0x0A, 0x00, 0x05, 0x00]);
    let labels = parse(
        &bytes,
        Path::new("000000.label"),
        LabelFormat::SemanticKitti,
        8,
    )
    .unwrap();
    assert_eq!(labels.class, vec![40, 10, 10, 50, 252, 10, 10, 72]);
    assert_eq!(labels.instance, vec![0, 5, 6, 0, 5, 0, 5, 0]);
    let t = labels.truth();
    assert_eq!(
        t.ground,
        vec![true, false, false, false, false, false, false, true]
    );
    assert_eq!(t.objects, vec![-1, 1, 2, -1, 3, -1, 1, -1]);
    assert_eq!(t.classes.get(&1).map(String::as_str), Some("car"));
    assert_eq!(t.classes.get(&3).map(String::as_str), Some("moving-car"));
    assert_eq!(t.without_instance, 1);
}

#[test]
fn a_label_count_that_differs_from_the_scan_names_the_file_and_both_counts() {
    let bytes = kitti_bytes(&[(40, 0), (40, 0), (40, 0)]);
    let err = parse(
        &bytes,
        Path::new("seq/labels/000007.label"),
        LabelFormat::SemanticKitti,
        5,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("seq/labels/000007.label"), "{err}");
    assert!(
        err.contains("3 labels") && err.contains("5 points"),
        "{err}"
    );
}

#[test]
fn a_truncated_label_file_names_the_leftover_bytes_and_offset() {
    let mut bytes = kitti_bytes(&[(40, 0), (40, 0)]);
    bytes.extend_from_slice(&[1, 2]);
    let err = parse(&bytes, Path::new("x.label"), LabelFormat::SemanticKitti, 2)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("10 bytes")
            && err.contains("2 bytes left over")
            && err.contains("byte offset 8"),
        "{err}"
    );
}

#[test]
fn an_unknown_class_names_the_point() {
    let bytes = kitti_bytes(&[(40, 0), (7, 0)]);
    let err = parse(&bytes, Path::new("x.label"), LabelFormat::SemanticKitti, 2)
        .unwrap_err()
        .to_string();
    assert!(err.contains("point 1 (0-based): class 7"), "{err}");
    let err = parse(
        &[24, 32],
        Path::new("t_lidarseg.bin"),
        LabelFormat::NuScenesLidarseg,
        2,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("point 1 (0-based): class 32"), "{err}");
}

#[test]
fn lidarseg_gives_ground_and_classes_but_no_instances() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("abc_lidarseg.bin");
    std::fs::write(&path, [24u8, 17, 30, 26, 0]).unwrap();
    let labels = read_labels_file(&path, None, 5).unwrap();
    assert_eq!(labels.format, LabelFormat::NuScenesLidarseg);
    let t = labels.truth();
    assert_eq!(t.ground, vec![true, false, false, true, false]);
    assert_eq!(t.objects, vec![-1; 5]);
    assert_eq!(t.without_instance, 1);
}

/// A `.npy` image of a one-dimensional array, written from NumPy's format description
/// (magic, version 1.0, little-endian header length, a dict padded with spaces to a
/// multiple of 64 bytes ending in a newline, then the data).
fn npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// An `.npz` as `np.savez_compressed(path, data=array)` writes it: a zip with a deflated
/// member `data.npy`.
fn npz(member: &str, npy: &[u8]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file(member, options).unwrap();
    zip.write_all(npy).unwrap();
    zip.finish().unwrap().into_inner()
}

#[test]
fn panoptic_npz_gives_ground_objects_and_classes() {
    // car #3, driveable surface, car #3, adult #1, vegetation, car without instance.
    let values: [u16; 6] = [17003, 24000, 17003, 2001, 30000, 17000];
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let bytes = npz("data.npy", &npy("<u2", "(6,)", &data));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tok_panoptic.npz");
    std::fs::write(&path, &bytes).unwrap();
    let labels = read_labels_file(&path, None, 6).unwrap();
    assert_eq!(labels.class, vec![17, 24, 17, 2, 30, 17]);
    assert_eq!(labels.instance, vec![3, 0, 3, 1, 0, 0]);
    let t = labels.truth();
    assert_eq!(t.ground, vec![false, true, false, false, false, false]);
    assert_eq!(t.objects, vec![1, -1, 1, 2, -1, -1]);
    assert_eq!(t.classes.get(&1).map(String::as_str), Some("vehicle.car"));
    assert_eq!(
        t.classes.get(&2).map(String::as_str),
        Some("human.pedestrian.adult")
    );
    assert_eq!(t.without_instance, 1);
}

#[test]
fn a_panoptic_file_of_another_type_or_shape_is_refused_with_the_reason() {
    let p = Path::new("t_panoptic.npz");
    let f32s = npz("data.npy", &npy("<f4", "(2,)", &[0; 8]));
    let err = parse(&f32s, p, LabelFormat::NuScenesPanoptic, 2)
        .unwrap_err()
        .to_string();
    assert!(err.contains("dtype '<f4'"), "{err}");
    let two_d = npz("data.npy", &npy("<u2", "(2, 1)", &[0; 4]));
    let err = parse(&two_d, p, LabelFormat::NuScenesPanoptic, 2)
        .unwrap_err()
        .to_string();
    assert!(err.contains("one dimension"), "{err}");
    let short = npz("data.npy", &npy("<u2", "(3,)", &[0; 4]));
    let err = parse(&short, p, LabelFormat::NuScenesPanoptic, 3)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("needs 6 data bytes") && err.contains("has 4"),
        "{err}"
    );
    let err = parse(b"PK\x03\x04garbage", p, LabelFormat::NuScenesPanoptic, 3)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("t_panoptic.npz") && err.contains("zip"),
        "{err}"
    );
    let two = {
        let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let o = zip::write::SimpleFileOptions::default();
        for m in ["a.npy", "b.npy"] {
            zip.start_file(m, o).unwrap();
            zip.write_all(&npy("<u2", "(1,)", &[0, 0])).unwrap();
        }
        zip.finish().unwrap().into_inner()
    };
    let err = parse(&two, p, LabelFormat::NuScenesPanoptic, 1)
        .unwrap_err()
        .to_string();
    assert!(err.contains("a.npy, b.npy"), "{err}");
}

#[test]
fn formats_are_told_by_name_and_unknown_names_are_refused() {
    assert_eq!(
        LabelFormat::detect(Path::new("labels/000001.label")),
        Some(LabelFormat::SemanticKitti)
    );
    assert_eq!(
        LabelFormat::detect(Path::new("x_lidarseg.bin")),
        Some(LabelFormat::NuScenesLidarseg)
    );
    assert_eq!(
        LabelFormat::detect(Path::new("x_panoptic.npz")),
        Some(LabelFormat::NuScenesPanoptic)
    );
    assert_eq!(LabelFormat::detect(Path::new("000001.bin")), None);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("labels.txt");
    std::fs::write(&path, "x").unwrap();
    let err = read_labels_file(&path, None, 1).unwrap_err().to_string();
    assert!(
        err.contains("labels.txt") && err.contains(".label"),
        "{err}"
    );
}
