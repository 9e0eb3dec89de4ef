//! Unit tests of the sweep's outputs.

use super::*;

#[test]
fn counts_print_as_integers_and_shares_with_three_decimals() {
    assert_eq!(format_value(Kind::Count, 16.0), "16");
    assert_eq!(format_value(Kind::Count, 41185.294), "41185.3");
    assert_eq!(format_value(Kind::Share, 1.0), "1.000");
    assert_eq!(format_value(Kind::Share, -0.0), "0.000");
    let same = tables::Interval {
        n: 3,
        mean: 16.0,
        lo: Some(16.0),
        hi: Some(16.0),
    };
    assert_eq!(format_interval(Kind::Count, &same), "16");
    let wide = tables::Interval {
        n: 3,
        mean: 0.5,
        lo: Some(-0.0001),
        hi: Some(1.0),
    };
    assert_eq!(format_interval(Kind::Share, &wide), "0.500 [0.000, 1.000]");
}

#[test]
fn every_metric_has_a_human_title() {
    for m in tables::metrics(&[]) {
        let p = presentation(&m.name, &m.label);
        assert!(!p.title.contains('_'), "{}: {}", m.name, p.title);
        assert!(p.title.ends_with(')'), "{}: no unit in {}", m.name, p.title);
        assert!(!p.title.starts_with(char::is_lowercase), "{}", p.title);
        assert!(!p.read.is_empty());
    }
}
