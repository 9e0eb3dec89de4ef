//! LAS 1.4 and LAZ output of one frame (point data record format 6), for GIS and
//! point-cloud tools (PDAL, LAStools, laspy, CloudCompare, QGIS).
//!
//! The frame is the same [`PlyFrame`] the PLY writer takes, so both formats carry the same
//! fields:
//!
//! | PLY property | LAS |
//! |---|---|
//! | `x`, `y`, `z` | X, Y, Z with scale 0.001 m and offset 0 (the sensor's quantum is 2 mm) |
//! | `intensity` | Intensity, the sensor's byte unscaled (0-255) |
//! | `time` | GPS Time: the return's absolute time, seconds past the hour as the HDL-32E stamps it (the sensor knows no GPS week); and the extra byte `time`, the PLY's value (seconds since the frame start, float) |
//! | `ground` | Classification 2 (ground), other reported returns 1 (unclassified), `convert` 0 (never classified); and the extra byte `ground` (1 or 0) |
//! | `fate` 1-3 (dropped) | Classification 7 (low noise) and the Withheld flag: the sensor did not report them |
//! | `fate` 4-5 (spurious echo) | ground or unclassified as any reported return, and the Synthetic flag (LAS 1.4: created by a technique other than the sensor's own measurement) |
//! | `ring`, `laser`, `azimuth`, `range`, `time`, `range_clean`, `power`, `ground`, `fate`, `cause`, `cluster` | extra bytes, described in the Extra Bytes VLR (LASF_Spec, record 4) under those names |
//!
//! Return number and number of returns are both 1: each return of a dual-return capture
//! is its own pulse record here. Provenance (the PLY's comment lines) is a VLR with user id
//! `lidar-noise`, record 1, one line per comment. The header's date and GUID are left
//! empty so that the same input gives the same bytes.

use super::ply::PlyFrame;
use super::Output;
use las::point::{Classification, Format};
use las::{Builder, Point, Transform, Vector, Version, Vlr};
use std::io::{Cursor, Write};

/// Scale of the X, Y and Z integers, metres.
pub const SCALE_M: f64 = 0.001;

/// User id of the provenance VLR.
pub const PROVENANCE_USER_ID: &str = "lidar-noise";

/// Record id of the provenance VLR.
pub const PROVENANCE_RECORD_ID: u16 = 1;

/// Type of an extra-bytes dimension, with its LAS data type code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExtraType {
    /// unsigned char (code 1).
    U8,
    /// long, 32-bit signed (code 6).
    I32,
    /// float (code 9).
    F32,
}

impl ExtraType {
    /// The LAS 1.4 data type code of the Extra Bytes descriptor.
    pub fn code(self) -> u8 {
        match self {
            ExtraType::U8 => 1,
            ExtraType::I32 => 6,
            ExtraType::F32 => 9,
        }
    }

    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            ExtraType::U8 => 1,
            ExtraType::I32 | ExtraType::F32 => 4,
        }
    }
}

/// One extra-bytes dimension: name, type and the description written in the VLR.
#[derive(Clone, Copy, Debug)]
pub struct ExtraDim {
    /// Name (as in the PLY).
    pub name: &'static str,
    /// Stored type.
    pub ty: ExtraType,
    /// Description (at most 31 characters, stored in the descriptor).
    pub description: &'static str,
}

const fn dim(name: &'static str, ty: ExtraType, description: &'static str) -> ExtraDim {
    ExtraDim {
        name,
        ty,
        description,
    }
}

/// Dimensions every file has, in record order.
pub const BASE_DIMS: [ExtraDim; 5] = [
    dim("ring", ExtraType::U8, "ring, 0 = lowest laser"),
    dim("laser", ExtraType::U8, "laser id (firing order)"),
    dim("azimuth", ExtraType::F32, "degrees clockwise from above"),
    dim("range", ExtraType::F32, "metres (after noise)"),
    dim("time", ExtraType::F32, "s since frame start (as PLY)"),
];

/// Optional dimensions, in record order, present when the frame has the column.
/// (`ground` is also the classification; the byte keeps it readable where a tool
/// reclassifies.)
pub const OPTIONAL_DIMS: [ExtraDim; 6] = [
    dim("range_clean", ExtraType::F32, "metres before noise"),
    dim("power", ExtraType::F32, "fraction of emitted power"),
    dim("ground", ExtraType::U8, "1 ground, 0 not"),
    dim("fate", ExtraType::U8, "0kept 1occl 2pow 3rng 4rep 5add"),
    dim("cause", ExtraType::U8, "stage index, 255 none/filters"),
    dim("cluster", ExtraType::I32, "cluster id, -1 = none"),
];

/// One frame as LAS (or LAZ when `compressed`).
#[derive(Clone, Copy, Debug)]
pub struct LasFrame<'a> {
    /// The frame and its columns, as for PLY (the encoding is ignored).
    pub frame: PlyFrame<'a>,
    /// Write LAZ (LASzip-compressed) instead of LAS.
    pub compressed: bool,
}

impl LasFrame<'_> {
    /// The extra dimensions this frame writes, in record order.
    pub fn dims(&self) -> Vec<ExtraDim> {
        let c = &self.frame.columns;
        let present = [
            c.range_clean.is_some(),
            c.power.is_some(),
            c.ground.is_some(),
            c.fate.is_some(),
            c.cause.is_some(),
            c.cluster.is_some(),
        ];
        BASE_DIMS
            .iter()
            .copied()
            .chain(
                OPTIONAL_DIMS
                    .iter()
                    .zip(present)
                    .filter_map(|(d, here)| here.then_some(*d)),
            )
            .collect()
    }

    /// The LAS header: version 1.4, point format 6 with the extra bytes, scale 1 mm.
    fn header(&self, dims: &[ExtraDim]) -> las::Result<las::Header> {
        let mut format = Format::new(6)?;
        format.extra_bytes = dims.iter().map(|d| d.ty.size() as u16).sum();
        format.is_compressed = self.compressed;
        let mut b = Builder::from(Version::new(1, 4));
        b.point_format = format;
        b.date = None;
        b.generating_software = format!("lidar-noise {}", env!("CARGO_PKG_VERSION"));
        b.system_identifier = "Velodyne HDL-32E".into();
        let t = Transform {
            scale: SCALE_M,
            offset: 0.0,
        };
        b.transforms = Vector { x: t, y: t, z: t };
        b.vlrs.push(Vlr {
            user_id: "LASF_Spec".into(),
            record_id: 4,
            description: "Extra Bytes".into(),
            data: dims.iter().flat_map(descriptor).collect(),
        });
        b.vlrs.push(Vlr {
            user_id: PROVENANCE_USER_ID.into(),
            record_id: PROVENANCE_RECORD_ID,
            description: "provenance".into(),
            data: self.frame.provenance_lines().join("\n").into_bytes(),
        });
        b.into_header()
    }

    /// The whole file in memory (the LAS writer seeks back to patch the header).
    pub fn to_bytes(&self) -> las::Result<Vec<u8>> {
        let dims = self.dims();
        let header = self.header(&dims)?;
        let mut writer = las::Writer::new(Cursor::new(Vec::new()), header)?;
        let c = self.frame.columns;
        let record_len: usize = dims.iter().map(|d| d.ty.size()).sum();
        for (i, r) in self.frame.returns.iter().enumerate() {
            let mut extra = Vec::with_capacity(record_len);
            extra.extend_from_slice(&[r.ring, r.laser]);
            extra.extend_from_slice(&r.azimuth.to_le_bytes());
            extra.extend_from_slice(&r.range.to_le_bytes());
            extra.extend_from_slice(&self.frame.relative_time(r).to_le_bytes());
            if let Some(v) = c.range_clean {
                extra.extend_from_slice(&v[i].to_le_bytes());
            }
            if let Some(v) = c.power {
                extra.extend_from_slice(&v[i].to_le_bytes());
            }
            if let Some(v) = c.ground {
                extra.push(v[i]);
            }
            let fate = c.fate.map_or(0, |v| v[i]);
            if c.fate.is_some() {
                extra.push(fate);
            }
            if let Some(v) = c.cause {
                extra.push(v[i]);
            }
            if let Some(v) = c.cluster {
                extra.extend_from_slice(&v[i].to_le_bytes());
            }
            // Dropped returns (fates 1-3) were never reported: noise, withheld. Spurious
            // echoes (4, 5) are reported returns, classified as any, flagged synthetic.
            let dropped = matches!(fate, 1..=3);
            let classification = if dropped {
                Classification::LowPoint
            } else {
                match c.ground {
                    Some(g) if g[i] != 0 => Classification::Ground,
                    Some(_) => Classification::Unclassified,
                    None => Classification::CreatedNeverClassified,
                }
            };
            writer.write_point(Point {
                x: f64::from(r.x),
                y: f64::from(r.y),
                z: f64::from(r.z),
                intensity: u16::from(r.intensity),
                return_number: 1,
                number_of_returns: 1,
                classification,
                is_withheld: dropped,
                is_synthetic: matches!(fate, 4 | 5),
                gps_time: Some(r.time),
                extra_bytes: extra,
                ..Point::default()
            })?;
        }
        Ok(writer.into_inner()?.into_inner())
    }
}

/// The 192-byte Extra Bytes descriptor of a dimension (LAS 1.4 R15, table 24).
fn descriptor(d: &ExtraDim) -> Vec<u8> {
    let mut out = vec![0u8; 192];
    out[2] = d.ty.code();
    // options = 0: no no_data, min, max, scale or offset.
    let name = d.name.as_bytes();
    out[4..4 + name.len().min(31)].copy_from_slice(&name[..name.len().min(31)]);
    let desc = d.description.as_bytes();
    let n = desc.len().min(31);
    out[160..160 + n].copy_from_slice(&desc[..n]);
    out
}

impl Output for LasFrame<'_> {
    fn extension(&self) -> &'static str {
        if self.compressed {
            "laz"
        } else {
            "las"
        }
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        self.frame
            .check()
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
        let bytes = self.to_bytes().map_err(std::io::Error::other)?;
        out.write_all(&bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptors_are_192_bytes_with_name_type_and_description() {
        let d = descriptor(&OPTIONAL_DIMS[5]);
        assert_eq!(d.len(), 192);
        assert_eq!(d[2], 6);
        assert_eq!(&d[4..11], b"cluster");
        assert_eq!(d[11], 0);
        assert_eq!(&d[160..167], b"cluster");
        for dim in BASE_DIMS.iter().chain(&OPTIONAL_DIMS) {
            assert!(dim.description.len() <= 31, "{}", dim.name);
        }
    }
}
