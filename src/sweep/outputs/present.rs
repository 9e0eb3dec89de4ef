//! How a metric is named, labelled and formatted on the sweep's page and plots.

use super::*;

/// Index of the varied key used as the plots' x axis: a rain rate if varied, else the
/// first numeric key.
pub fn x_axis(varies: &[Vary]) -> Option<usize> {
    varies
        .iter()
        .position(|v| v.key.ends_with("rate_mm_h") && v.is_numeric())
        .or_else(|| varies.iter().position(|v| v.is_numeric()))
}

pub(super) fn x_label(v: &Vary) -> String {
    if v.key.ends_with("rate_mm_h") {
        "rain rate (mm/h)".into()
    } else {
        v.key.clone()
    }
}

pub(super) fn safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// What a metric measures, for its axis and its number format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A share in [0, 1]: three decimals, y axis 0 to 1.
    Share,
    /// A count (per frame): whole numbers as integers, other means with one decimal;
    /// integer axis ticks.
    Count,
    /// A length in metres, with the given decimals.
    Metres(usize),
}

/// How a metric is shown: title with its unit, kind, and how to read its plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Presentation {
    /// Human title with the unit, e.g. "Objects detected (share)".
    pub title: String,
    /// Share, count or length.
    pub kind: Kind,
    /// One sentence on how to read the plot.
    pub read: String,
}

pub(super) fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// The presentation of metric `name` whose table label (with unit) is `label`: fixed
/// titles and reading notes for the known metrics, the capitalised label otherwise (per
/// band and per class metrics carry their band or class in the label).
pub fn presentation(name: &str, label: &str) -> Presentation {
    let kind = if label.ends_with("(count)") {
        Kind::Count
    } else if label.ends_with("(m)") {
        Kind::Metres(if name.starts_with("range_change") {
            3
        } else {
            1
        })
    } else {
        Kind::Share
    };
    let fixed: Option<(&str, &str)> = match name {
        "detected_share" => Some(("Objects detected (share)", "Share of the objects that one noisy cluster still holds (half of the returns that reach clustering, purity >= 0.5); higher is better.")),
        "retained_share" => Some(("Objects retained (share)", "Like detected, but against all of the object's clean returns, so returns dropped by noise count against it; higher is better.")),
        "split_share" => Some(("Objects split (share)", "Share of the objects broken over two or more noisy clusters; lower is better.")),
        "merged_share" => Some(("Objects merged (share)", "Share of the objects that are the minority of a cluster made mostly of other returns; lower is better.")),
        "merged_into_ground_share" => Some(("Objects merged into ground (share)", "Share of the objects whose reaching returns are mostly labelled ground; lower is better.")),
        "lost_share" => Some(("Objects lost (share)", "Share of the objects with no outcome above, e.g. none of their returns reach clustering; lower is better.")),
        "objects" => Some(("Objects per frame (count)", "Objects counted per frame; the same in every cell of a capture, so a check rather than a result.")),
        "object_survival" => Some(("Object survival (share, IoU >= 0.5)", "Share of the clean object clusters that a noisy cluster matches with IoU >= 0.5 (the older rule); higher is better.")),
        "kept" => Some(("Returns kept per frame (count)", "Returns that pass every noise stage and the detection filters; falls as noise removes returns.")),
        "occluded" => Some(("Returns occluded per frame (count)", "Returns blocked by the occlusion stage.")),
        "below_power" => Some(("Returns below the power threshold per frame (count)", "Returns whose power after the noise stages is under detection.min_power; rain's extinction raises it.")),
        "below_min_range" => Some(("Returns below the minimum range per frame (count)", "Returns closer than detection.min_range_m, e.g. rain drops at the window.")),
        "range_change_mean_m" => Some(("Mean range change of kept returns (m)", "Noisy minus clean range, averaged over kept returns; 0 means no bias.")),
        "range_change_rms_m" => Some(("RMS range change of kept returns (m)", "Root mean square of noisy minus clean range; grows with the range noise.")),
        "range_change_p95_m" => Some(("95th percentile of the range change (m)", "95 % of the kept returns moved less than this.")),
        "clusters" => Some(("Clusters per frame (count)", "Every cluster with at least min_points returns; noise can add or remove clusters.")),
        "object_clusters" => Some(("Object clusters per frame (count)", "Clusters that pass the object rule (height and footprint)." )),
        "matched" => Some(("Clean object clusters matched per frame (count)", "Clean object clusters that a noisy cluster matches with IoU >= 0.5; higher is better.")),
        "false_clusters" => Some(("False object clusters per frame (count)", "Noisy clusters made mostly of returns that belong to no clean object cluster; lower is better.")),
        "farthest_matched_m" => Some(("Farthest matched object cluster (m)", "Horizontal distance of the farthest matched clean object cluster; falls when far objects are lost.")),
        "ground_precision" => Some(("Ground precision (share)", "Share of the returns labelled ground that are ground, over the returns that reach ground removal; higher is better.")),
        "ground_recall" => Some(("Ground recall (share)", "Share of the ground returns reaching ground removal that are labelled ground; higher is better.")),
        "ground_lost_before_share" => Some(("Ground returns dropped before ground removal (share)", "Share of the ground returns removed by the noise stages or the detection filters before ground removal.")),
        _ => None,
    };
    if let Some((title, read)) = fixed {
        return Presentation {
            title: title.into(),
            kind,
            read: read.into(),
        };
    }
    let read = if name.starts_with("objects_") {
        "Objects per frame whose clean centroid lies in this distance band."
    } else if name.contains("_share_") && label.contains(" at ") {
        "Share of the objects in this distance band (horizontal distance of the clean centroid) with this outcome."
    } else if name.starts_with("detected_share_") {
        "Share of the labelled objects of this kind that are detected; higher is better."
    } else {
        match kind {
            Kind::Share => "A share between 0 and 1.",
            Kind::Count => "A count per frame.",
            Kind::Metres(_) => "A length in metres.",
        }
    };
    Presentation {
        title: capitalised(label),
        kind,
        read: read.into(),
    }
}

/// Formats a count: whole numbers without decimals, other means with one.
pub(super) fn format_count(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        figure::format_number(v.round(), 0)
    } else {
        figure::format_number(v, 1)
    }
}

/// Formats a value of a metric of kind `kind`.
pub fn format_value(kind: Kind, v: f64) -> String {
    match kind {
        Kind::Share => figure::format_number(v, 3),
        Kind::Count => format_count(v),
        Kind::Metres(d) => figure::format_number(v, d),
    }
}

/// Formats a mean and its interval; the interval is left out when it has no width at
/// the printed precision (every seed gave the same value) or there is none (one seed).
pub fn format_interval(kind: Kind, i: &tables::Interval) -> String {
    let mean = format_value(kind, i.mean);
    match (i.lo, i.hi) {
        (Some(lo), Some(hi)) => {
            let (lo, hi) = (format_value(kind, lo), format_value(kind, hi));
            if lo == mean && hi == mean {
                mean
            } else {
                format!("{mean} [{lo}, {hi}]")
            }
        }
        _ => mean,
    }
}
