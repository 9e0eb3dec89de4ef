//! Spurious echoes downstream of the chain, through the real binary: sweeps count an
//! object cluster made of echoes only as a false cluster and never credit echoes to an
//! object; `run` reports them apart and its PLY says which points are echoes.

use crate::common;

use crate::common::bin;
use std::collections::BTreeMap;
use std::path::Path;

/// A fake car (spoofing, p-diagram 14) 8 m to the right of the sensor, where the
/// crossroad fixture has free road: its points can only form a cluster of their own.
const SPOOF: &str = "seed = 3\n[[noise]]\ntype = \"spoofing\"\nazimuth_deg = 90.0\nrange_m = 8.0\n";

/// Rows of a CSV file as maps from column name to text.
fn rows(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            head.iter()
                .zip(l.split(','))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

fn num(row: &BTreeMap<String, String>, key: &str) -> i64 {
    row[key]
        .parse()
        .unwrap_or_else(|_| panic!("{key} = {}", row[key]))
}

#[test]
fn a_spoofed_object_is_a_false_cluster_and_no_detection() {
    let tmp = tempfile::tempdir().unwrap();
    let config = tmp.path().join("spoof.toml");
    std::fs::write(&config, SPOOF).unwrap();
    let out = tmp.path().join("sweep");
    bin()
        .args(["-q", "sweep"])
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg("-c")
        .arg(&config)
        .args(["--vary", "spoofing=on,off", "--seeds", "1..2", "-o"])
        .arg(&out)
        .assert()
        .success();
    let all = rows(&out.join("sweep.csv"));
    let key = |r: &BTreeMap<String, String>| (r["seed"].clone(), r["frame"].clone());
    let off: BTreeMap<_, _> = all
        .iter()
        .filter(|r| r["spoofing"] == "off")
        .map(|r| (key(r), r))
        .collect();
    let on: Vec<_> = all.iter().filter(|r| r["spoofing"] == "on").collect();
    assert!(on.len() >= 2, "{} rows", on.len());
    for r in on {
        let o = off[&key(r)];
        // The fake car is one more object cluster, from no recorded return.
        assert_eq!(num(r, "object_clusters"), num(o, "object_clusters") + 1);
        assert_eq!(num(r, "false_clusters"), num(o, "false_clusters") + 1);
        // It is no labelled object and takes nothing from the real ones.
        assert_eq!(num(r, "objects"), num(o, "objects"));
        assert_eq!(num(r, "detected"), num(o, "detected"));
        assert_eq!(num(r, "retained"), num(o, "retained"));
        // Its points are reported (kept counts every reported return): in place of
        // recorded returns behind them (clear air keeps every recorded return, so the
        // count does not fall) or in empty slots.
        assert!(num(r, "kept") >= num(o, "kept"));
    }
}

#[test]
fn run_reports_echoes_apart_and_marks_them_in_the_ply() {
    let tmp = tempfile::tempdir().unwrap();
    let config = tmp.path().join("spoof.toml");
    std::fs::write(&config, SPOOF).unwrap();
    let out = tmp.path().join("run");
    let assert = bin()
        .arg("run")
        .arg(common::fixtures().join("crossroad.pcap"))
        .arg("-c")
        .arg(&config)
        .args(["--frames", "0..0", "-o"])
        .arg(&out)
        .assert()
        .success();
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    let stdout = String::from_utf8_lossy(&assert.get_output().stdout).to_string();
    let message = format!("{stdout}{stderr}");
    assert!(message.contains("added as spurious echoes"), "{message}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("crossroad/summary.json")).unwrap())
            .unwrap();
    let sp = &summary["totals"]["noise"]["spurious"];
    let added = sp["added"].as_u64().unwrap_or(0) + sp["replaced"].as_u64().unwrap_or(0);
    assert!(added > 10, "{sp}");
    // The PLY of kept returns carries fate and cause: the echoes are fate 4 or 5 with
    // cause 0 (the spoofing stage), and their count is the summary's.
    let ply = std::fs::read(out.join("crossroad/frame_00000.ply")).unwrap();
    let end = b"end_header\n";
    let at = ply.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = String::from_utf8_lossy(&ply[..at]).to_string();
    assert!(
        header.contains("property uchar fate\nproperty uchar cause\n"),
        "{header}"
    );
    let props: Vec<(&str, usize)> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property "))
        .map(|l| {
            let mut p = l.split(' ');
            let ty = p.next().unwrap();
            let size = match ty {
                "float" | "int" => 4,
                "uchar" => 1,
                t => panic!("type {t}"),
            };
            (p.next().unwrap(), size)
        })
        .collect();
    let stride: usize = props.iter().map(|p| p.1).sum();
    let offset =
        |name: &str| -> usize { props.iter().take_while(|p| p.0 != name).map(|p| p.1).sum() };
    let (fate_at, cause_at) = (offset("fate"), offset("cause"));
    let body = &ply[at..];
    assert_eq!(body.len() % stride, 0);
    let mut echoes = 0u64;
    for point in body.chunks(stride) {
        let (fate, cause) = (point[fate_at], point[cause_at]);
        match fate {
            0 => assert_eq!(cause, 255),
            4 | 5 => {
                assert_eq!(cause, 0);
                echoes += 1;
            }
            f => panic!("a kept-returns PLY holds fate {f}"),
        }
    }
    assert_eq!(echoes, added);
}
