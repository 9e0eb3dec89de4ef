//! A noisy point-cloud scan written back in the format it was read from (KITTI `.bin`,
//! nuScenes `.pcd.bin`, PCD, CSV), with a per-point sidecar CSV saying what became of each
//! point (issue 31, "Outputs in the input's own format and layout"): a detector trained on
//! the dataset reads the noisy scan as it reads the clean one.
//!
//! Layouts, as the readers of `crate::cloud` read them: KITTI x y z reflectance (float32
//! LE, reflectance = byte / 255), nuScenes x y z intensity ring (float32 LE), PCD 0.7
//! `DATA binary` with fields x y z intensity ring (F4, F4, F4, F4, U2), CSV with the
//! header `x,y,z,intensity,ring`.

use super::Output;
use crate::cloud::Format;
use std::fmt::Write as _;
use std::io::Write;

/// One point of a noisy scan and what became of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanPoint {
    /// Position after noise, metres.
    pub x: f32,
    /// y, metres.
    pub y: f32,
    /// z, metres.
    pub z: f32,
    /// The intensity byte after noise.
    pub intensity: u8,
    /// Ring (0 = lowest beam).
    pub ring: u16,
    /// Index of the point in the input scan (`None` for an echo the noise added).
    pub point: Option<u32>,
    /// Fate code (see summary.json's `fate_codes`).
    pub fate: u8,
    /// Stage index that decided the fate (255: none).
    pub cause: u8,
    /// Range before noise, metres (0 for an added echo).
    pub range_clean: f32,
    /// 1 when ground removal labelled it ground.
    pub ground: u8,
    /// Cluster id (-1: ground or noise).
    pub cluster: i32,
}

/// The noisy scan in `format`.
pub struct Scan<'a> {
    /// The format written.
    pub format: Format,
    /// The points, in the order written.
    pub points: &'a [ScanPoint],
    /// Each point's time as the input stored it (PCD and CSV write it as a `time`
    /// field when given; the other formats have none).
    pub times: Option<&'a [f64]>,
}

/// File name extension of a scan written in `format`.
pub fn extension(format: Format) -> &'static str {
    match format {
        Format::Kitti => "bin",
        Format::NuScenes => "pcd.bin",
        Format::Pcd => "pcd",
        Format::Csv => "csv",
    }
}

impl Output for Scan<'_> {
    fn extension(&self) -> &'static str {
        extension(self.format)
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        if let Some(times) = self.times {
            if times.len() != self.points.len() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "{} times for {} points: give one a point",
                        times.len(),
                        self.points.len()
                    ),
                ));
            }
        }
        match self.format {
            // Points gathered a chunk at a time into a buffer, one `write_all` a chunk: a
            // call through `dyn Write` for every 4-byte value (a small `memcpy` each) was
            // a twentieth of a dataset run.
            Format::Kitti => write_records(out, self.points, |_, p| kitti_record(p))?,
            Format::NuScenes => write_records(out, self.points, |_, p| nuscenes_record(p))?,
            Format::Pcd => {
                let n = self.points.len();
                // The time field, where given, after the others.
                let (field, size, kind, count) = match self.times {
                    Some(_) => (" time", " 8", " F", " 1"),
                    None => ("", "", "", ""),
                };
                write!(
                    out,
                    "# .PCD v0.7 - lidar-noise\nVERSION 0.7\nFIELDS x y z intensity ring{field}\n\
                     SIZE 4 4 4 4 2{size}\nTYPE F F F F U{kind}\nCOUNT 1 1 1 1 1{count}\n\
                     WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n"
                )?;
                match self.times {
                    Some(times) => write_records(out, self.points, |k, p| {
                        let mut record = [0u8; 26];
                        record[..18].copy_from_slice(&pcd_record(p));
                        record[18..].copy_from_slice(&times[k].to_le_bytes());
                        record
                    })?,
                    None => write_records(out, self.points, |_, p| pcd_record(p))?,
                }
            }
            Format::Csv => {
                let field = if self.times.is_some() { ",time" } else { "" };
                writeln!(out, "x,y,z,intensity,ring{field}")?;
                for (k, p) in self.points.iter().enumerate() {
                    write!(out, "{},{},{},{},{}", p.x, p.y, p.z, p.intensity, p.ring)?;
                    match self.times {
                        Some(times) => writeln!(out, ",{}", times[k])?,
                        None => writeln!(out)?,
                    }
                }
            }
        }
        Ok(())
    }
}

/// The little-endian bytes of `N` floats, one after the other.
fn floats_le<const N: usize, const B: usize>(values: [f32; N]) -> [u8; B] {
    const { assert!(B == 4 * N, "B must be the bytes of N floats") };
    let mut bytes = [0u8; B];
    for (chunk, v) in bytes.chunks_exact_mut(4).zip(values) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    bytes
}

/// A PCD record of `p` without a time: x y z intensity (float32), ring (u16).
fn pcd_record(p: &ScanPoint) -> [u8; 18] {
    let mut record = [0u8; 18];
    record[..16].copy_from_slice(&floats_le::<4, 16>([p.x, p.y, p.z, f32::from(p.intensity)]));
    record[16..].copy_from_slice(&p.ring.to_le_bytes());
    record
}

/// Writes `record(k, p)` for every point `p` (index `k`), 64 KB at a time.
fn write_records<const B: usize>(
    out: &mut dyn Write,
    points: &[ScanPoint],
    record: impl Fn(usize, &ScanPoint) -> [u8; B],
) -> std::io::Result<()> {
    let per_chunk = (64 << 10) / B;
    let mut buf = Vec::with_capacity(per_chunk * B);
    for (c, chunk) in points.chunks(per_chunk).enumerate() {
        buf.clear();
        for (j, p) in chunk.iter().enumerate() {
            buf.extend_from_slice(&record(c * per_chunk + j, p));
        }
        out.write_all(&buf)?;
    }
    Ok(())
}

/// The sidecar CSV: one row per point of the scan written, in the same order.
pub struct Fates<'a> {
    /// The points, in the order of the scan written.
    pub points: &'a [ScanPoint],
}

/// Header of the sidecar CSV.
pub const FATES_HEADER: &str = "point,fate,cause,range_clean,ground,cluster";

impl Output for Fates<'_> {
    fn extension(&self) -> &'static str {
        "fate.csv"
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        let mut rows = FateRows::new();
        for p in self.points {
            rows.push(p);
            if rows.full() {
                out.write_all(rows.take())?;
            }
        }
        out.write_all(rows.take())
    }
}

/// The fate CSV built a row at a time into a buffer of [`CHUNK`] bytes and more, header
/// first: taken whenever [`FateRows::full`] (or at the end) and written by the caller.
pub(crate) struct FateRows {
    buf: Vec<u8>,
    at: usize,
    floats: ryu::Buffer,
    /// The digits of the last point index written, as the bytes of a big-endian `u64`
    /// padded with '0' on the left (indices below 10^8), and that index: rows come in
    /// input order, so the next index is nearly always the one after it, whose text is
    /// this one's counted up, without a branch (formatting each index afresh was an
    /// eighth of the sidecar's time; counting up with a loop over the carries, whose
    /// length is a coin toss, saved a quarter of that).
    index: u64,
    last: Option<u32>,
}

/// Eight '0' bytes.
const ZEROS: u64 = u64::from_ne_bytes([b'0'; 8]);

/// Eight '9' bytes.
const NINES: u64 = u64::from_ne_bytes([b'9'; 8]);

/// Point indices from here on are written afresh (more digits than `FateRows::index`
/// holds).
const COUNTED_BELOW: u32 = 100_000_000;

impl FateRows {
    /// An empty CSV but for its header.
    pub(crate) fn new() -> Self {
        let mut buf = vec![0u8; CHUNK + ROW_MAX];
        let header = FATES_HEADER.len();
        buf[..header].copy_from_slice(FATES_HEADER.as_bytes());
        buf[header] = b'\n';
        FateRows {
            buf,
            at: header + 1,
            floats: ryu::Buffer::new(),
            index: ZEROS,
            last: None,
        }
    }

    /// Makes `index` the digits of `point` (below [`COUNTED_BELOW`]): counted up from the
    /// last one's where it is the next, else written afresh.
    #[inline]
    fn set_index(&mut self, point: u32) {
        if self.last.is_some_and(|l| l + 1 == point) {
            // The trailing nines become zeros and the digit before them goes up by one
            // ('0' padding on the left makes that a digit too): 9 off each trailing nine,
            // one on the digit before. The last index was below 10^8 - 1, so not all eight
            // digits are nines: t is at most 7.
            let t = (self.index ^ NINES).trailing_zeros() / 8;
            let low = (1u64 << (8 * t)) - 1;
            self.index = self.index - (0x0909_0909_0909_0909 & low) + (1u64 << (8 * t));
        } else {
            // The first digit in the highest byte.
            self.index = eight_digits(point).swap_bytes();
        }
        self.last = Some(point);
    }

    /// The text of `index` left-aligned in 8 bytes, and its length.
    #[inline]
    fn index_text(&self) -> ([u8; 8], usize) {
        // Leading '0' bytes are padding (all but the last digit of 0).
        let pad = (((self.index ^ ZEROS).leading_zeros() / 8) as usize).min(7);
        ((self.index << (8 * pad)).to_be_bytes(), 8 - pad)
    }

    /// Appends the row of `p`.
    #[inline]
    pub(crate) fn push(&mut self, p: &ScanPoint) {
        // Each row is written in place into a buffer of fixed length, each field without
        // a growth check or a `memcpy` call: the formatting machinery through a `dyn
        // Write` was a fifth of a dataset run, and then a copy and a growth check a field
        // (`push` and `extend_from_slice` on a `Vec`) most of what was left. The bytes
        // are those `writeln!` wrote.
        let index = p.point.filter(|&i| i < COUNTED_BELOW).map(|point| {
            self.set_index(point);
            self.index_text()
        });
        let space: &mut [u8; ROW_MAX] = (&mut self.buf[self.at..self.at + ROW_MAX])
            .try_into()
            .expect("a chunk has room for a row");
        let mut row = Row {
            bytes: space,
            len: 0,
        };
        match (index, p.point) {
            // All 8 bytes (one copy of fixed size), the row advanced by the text's.
            (Some((text, len)), _) => {
                row.bytes[..8].copy_from_slice(&text);
                row.len = len;
            }
            (None, Some(point)) => row.uint(point),
            (None, None) => row.text(b"-1"),
        }
        row.byte(b',');
        row.small(p.fate);
        row.small(p.cause);
        row.float(&mut self.floats, p.range_clean);
        row.byte(b',');
        row.small(p.ground);
        // The sign written either way and kept when negative: no branch (ground and
        // clusters alternate along the rows).
        row.bytes[row.len] = b'-';
        row.len += usize::from(p.cluster < 0);
        row.small_uint(p.cluster.unsigned_abs());
        row.byte(b'\n');
        self.at += row.len;
    }

    /// Whether a chunk's worth of rows is waiting.
    #[inline]
    pub(crate) fn full(&self) -> bool {
        self.at >= CHUNK
    }

    /// The rows waiting, now taken.
    pub(crate) fn take(&mut self) -> &[u8] {
        let n = std::mem::take(&mut self.at);
        &self.buf[..n]
    }
}

/// Writes a scan of fixed binary records (KITTI, nuScenes) and its fate CSV in one pass
/// over `rows` taken in `order`, each file's bytes handed to `scan` and `fates` a chunk
/// at a time: rows put in order first and then read once a file were three more passes
/// over them (a tenth of a KITTI dataset run). `None` for the other formats.
pub(crate) fn write_scan_and_fates<E>(
    format: Format,
    rows: &[ScanPoint],
    order: &[u32],
    scan: &mut dyn FnMut(&[u8]) -> Result<(), E>,
    fates: &mut dyn FnMut(&[u8]) -> Result<(), E>,
) -> Option<Result<(), E>> {
    match format {
        Format::Kitti => Some(both(rows, order, scan, fates, kitti_record)),
        Format::NuScenes => Some(both(rows, order, scan, fates, nuscenes_record)),
        Format::Pcd | Format::Csv => None,
    }
}

/// [`write_scan_and_fates`] for records of `B` bytes.
fn both<E, const B: usize>(
    rows: &[ScanPoint],
    order: &[u32],
    scan: &mut dyn FnMut(&[u8]) -> Result<(), E>,
    fates: &mut dyn FnMut(&[u8]) -> Result<(), E>,
    record: fn(&ScanPoint) -> [u8; B],
) -> Result<(), E> {
    let per_chunk = (64 << 10) / B;
    let mut buf = Vec::with_capacity(per_chunk * B);
    let mut csv = FateRows::new();
    // The rows of a chunk gathered first, in a loop of their own: each is a read from
    // anywhere in the rows, and with the formatting in the same loop fewer of those reads
    // were under way at once (4 % slower than putting all the rows in order first).
    let mut gathered = Vec::with_capacity(per_chunk);
    for chunk in order.chunks(per_chunk) {
        gathered.clear();
        gathered.extend(chunk.iter().map(|&j| rows[j as usize]));
        buf.clear();
        for p in &gathered {
            buf.extend_from_slice(&record(p));
            csv.push(p);
            if csv.full() {
                fates(csv.take())?;
            }
        }
        scan(&buf)?;
    }
    fates(csv.take())
}

/// A KITTI record of `p`: x y z reflectance (float32, reflectance the byte over 255).
fn kitti_record(p: &ScanPoint) -> [u8; 16] {
    floats_le::<4, 16>([p.x, p.y, p.z, f32::from(p.intensity) / 255.0])
}

/// A nuScenes record of `p`: x y z intensity ring (float32).
fn nuscenes_record(p: &ScanPoint) -> [u8; 20] {
    floats_le::<5, 20>([p.x, p.y, p.z, f32::from(p.intensity), f32::from(p.ring)])
}

/// Longest row of the fate CSV: a point index and a cluster id of 10 digits and a sign,
/// three bytes, five commas and a newline (37), and the longest text `Display` gives an
/// f32 (48, 1e-45 written out).
const ROW_MAX: usize = 96;

/// Bytes of rows written at a time.
const CHUNK: usize = 64 * 1024;

/// One row of the fate CSV as it is built, in the room left in the buffer.
struct Row<'a> {
    bytes: &'a mut [u8; ROW_MAX],
    len: usize,
}

/// "00", "01", ... "99": two digits a step.
const DIGIT_PAIRS: &[u8; 200] = b"\
0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

impl Row<'_> {
    #[inline]
    fn byte(&mut self, b: u8) {
        self.bytes[self.len] = b;
        self.len += 1;
    }

    #[inline]
    fn text(&mut self, s: &[u8]) {
        self.bytes[self.len..self.len + s.len()].copy_from_slice(s);
        self.len += s.len();
    }

    /// Appends `v` in decimal and a comma: four bytes copied from a table and the length
    /// added (the fate, cause and ground bytes; one to three digits, whose varying count
    /// mispredicted `uint`'s branches).
    #[inline(always)]
    fn small(&mut self, v: u8) {
        let (text, len) = SMALL[usize::from(v)];
        self.bytes[self.len..self.len + 4].copy_from_slice(&text);
        self.len += usize::from(len);
    }

    /// Appends `digits / 10^places` with `places` (at least 1) digits after the point,
    /// where that is the shortest text of `v` ([`shortest_fixed`]), so `v`'s whole part
    /// is the text's.
    #[inline]
    fn fixed(&mut self, v: f32, digits: u64, places: u32) {
        if v < 0.0 {
            self.byte(b'-');
        }
        // No integer lies between v and its text (it would be a shorter text), so the
        // whole parts agree: `as` truncates, and v is below 2^20.
        let whole = v.abs() as u32;
        // Below 10^places, and places is at most 8 (`PLACES` of shifts to 26).
        let fraction = (digits - u64::from(whole) * POW10[places as usize]) as u32;
        self.small_uint(whole);
        self.byte(b'.');
        // The fraction's eight digits as one word, shifted past the leading ones not
        // wanted: no branch on the count of places, which changes from row to row (a
        // loop a pair and a last odd digit mispredicted as it did).
        let word = eight_digits(fraction) >> ((8 - places) * 8);
        // Eight bytes: the row has room past its longest text.
        self.bytes[self.len..self.len + 8].copy_from_slice(&word.to_le_bytes());
        self.len += places as usize;
    }

    /// Appends `v` in decimal: below 1000 (a scan's cluster ids, a range's whole metres)
    /// four bytes copied from a table and the length added, where `uint`'s branches on
    /// the count of digits, which changes from row to row, mispredicted.
    #[inline(always)]
    fn small_uint(&mut self, v: u32) {
        match THOUSAND.get(v as usize) {
            Some(&(text, len)) => {
                self.bytes[self.len..self.len + 4].copy_from_slice(&text);
                self.len += usize::from(len);
            }
            None => self.uint(v),
        }
    }

    /// Appends `v` in decimal, two digits a step from the last.
    #[inline(always)]
    fn uint(&mut self, v: u32) {
        let digits = (v | 1).ilog10() as usize + 1;
        let mut at = self.len + digits;
        let mut rest = v;
        while rest >= 100 {
            let pair = (rest % 100) as usize * 2;
            rest /= 100;
            at -= 2;
            self.bytes[at..at + 2].copy_from_slice(&DIGIT_PAIRS[pair..pair + 2]);
        }
        if rest >= 10 {
            let pair = rest as usize * 2;
            self.bytes[at - 2..at].copy_from_slice(&DIGIT_PAIRS[pair..pair + 2]);
        } else {
            self.bytes[at - 1] = b'0' + rest as u8;
        }
        self.len += digits;
    }

    /// Appends `v` as `Display` writes it. ryu gives the same shortest round-trip
    /// digits, but for the ".0" it adds to whole numbers (written here as integers, as
    /// `Display` writes them), the exponent it uses below 1e-5 and from 1e16, and the
    /// way it breaks an exact tie between two shortest texts (to even, where `Display`
    /// rounds up: 1.00390625 is "1.0039063", ryu's "1.0039062"). Floats that can tie
    /// and those outside [1e-4, 1e6) go to `Display`.
    #[inline]
    fn float(&mut self, floats: &mut ryu::Buffer, v: f32) {
        // Whole: `as` truncates (one instruction; `fract` is a libm call on x86-64).
        if (v as i32) as f32 == v && v.abs() < 16_777_216.0 {
            // Every whole f32 below 2^24 is its own shortest text: no other integer of
            // fewer digits rounds to it.
            if v.is_sign_negative() {
                self.byte(b'-');
            }
            self.uint(v.abs() as u32);
            return;
        }
        if let Some((digits, places)) = shortest_fixed(v) {
            self.fixed(v, digits, places);
            return;
        }
        if (1e-4..1e6).contains(&v.abs()) && !may_tie(v) {
            self.text(floats.format_finite(v).as_bytes());
            return;
        }
        let mut s = String::new();
        // Writing to a String cannot fail.
        let _ = write!(s, "{v}");
        self.text(s.as_bytes());
    }
}

/// The eight decimal digits of `v` (below 10^8), '0'-padded on the left, as the bytes of
/// a little-endian word: the first digit in the lowest byte.
#[inline(always)]
fn eight_digits(v: u32) -> u64 {
    debug_assert!(v < 100_000_000);
    let pair = |p: u32| {
        let p = p as usize * 2;
        u64::from(u16::from_le_bytes([DIGIT_PAIRS[p], DIGIT_PAIRS[p + 1]]))
    };
    let (high, low) = (v / 10_000, v % 10_000);
    pair(high / 100) | pair(high % 100) << 16 | pair(low / 100) << 32 | pair(low % 100) << 48
}

/// 10^k for k in 0..=9.
const POW10: [u64; 10] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
];

/// Per shift s (0..=31): the fewest decimal places d with 10^d >= 2^s.
const PLACES: [u32; 32] = {
    let mut table = [0u32; 32];
    let mut s = 0;
    while s < 32 {
        let (mut d, mut p) = (0, 1u64);
        while p < 1u64 << s {
            p *= 10;
            d += 1;
        }
        table[s] = d;
        s += 1;
    }
    table
};

/// `v` (below 1000) in decimal, padded to four bytes, and the text's length.
const fn decimal(v: usize) -> ([u8; 4], usize) {
    let (mut text, mut len) = ([0u8; 4], 0);
    if v >= 100 {
        text[len] = b'0' + (v / 100) as u8;
        len += 1;
    }
    if v >= 10 {
        text[len] = b'0' + (v / 10 % 10) as u8;
        len += 1;
    }
    text[len] = b'0' + (v % 10) as u8;
    (text, len + 1)
}

/// 0 to 999 in decimal, padded to four bytes, and the text's length.
const THOUSAND: [([u8; 4], u8); 1000] = {
    let mut table = [([0u8; 4], 0u8); 1000];
    let mut v = 0;
    while v < 1000 {
        let (text, len) = decimal(v);
        table[v] = (text, len as u8);
        v += 1;
    }
    table
};

/// Each byte in decimal followed by a comma, padded to four bytes, and that text's length.
const SMALL: [([u8; 4], u8); 256] = {
    let mut table = [([0u8; 4], 0u8); 256];
    let mut v = 0;
    while v < 256 {
        let (mut text, len) = decimal(v);
        text[len] = b',';
        table[v] = (text, len as u8 + 1);
        v += 1;
    }
    table
};

/// The shortest text of `v` that reads back as `v`, the one nearest `v` where several
/// are as short, as `digits` and the number of decimal `places` (at least 1): for `|v|` in
/// [1/8, 2^20), not whole and not a power of two, and only where no two texts tie; `None`
/// otherwise (the caller then asks ryu or `Display`).
///
/// Why by hand: this is ryu's result (and `Display`'s) for the clean ranges of a scan's
/// fate file, a third cheaper a row (ryu was a tenth of a KITTI dataset run): the range
/// of reals that round to `v` is found in integers at the fewest places where it is a
/// decimal step wide, then narrowed a place at a time while it holds a multiple of ten;
/// the text is the integer nearest `v` at the places left. The unit tests check it
/// against `Display` on every f32 of [1/8, 2^20) (`--ignored`) and on a sample.
#[inline]
fn shortest_fixed(v: f32) -> Option<(u64, u32)> {
    let bits = v.to_bits() & 0x7fff_ffff;
    let biased = bits >> 23;
    let fraction = bits & 0x7f_ffff;
    // |v| in [2^-3, 2^20) and a mantissa other than 1 (whose lower neighbour is nearer).
    if !(124..147).contains(&biased) || fraction == 0 {
        return None;
    }
    let m = u64::from(fraction | 0x80_0000);
    // |v| = m / 2^s, s in 4..=26; the reals that round to it: (2m -+ 1) / 2^(s + 1),
    // the ends included where m is even (rounding to even keeps them at v).
    let s = 150 - biased;
    let d0 = PLACES[s as usize];
    let p = POW10[d0 as usize];
    let shift = s + 1;
    let mask = (1u64 << shift) - 1;
    let odd = m & 1;
    // Below 2^25 10^8 < 2^52: no overflow.
    let (lo, hi) = ((2 * m - 1) * p, (2 * m + 1) * p);
    // The integers in the range at d0 places: a..=b, at least one (it is over 1 wide).
    let a = ((lo + mask) >> shift) + (odd & u64::from(lo & mask == 0));
    let b = (hi >> shift) - (odd & u64::from(hi & mask == 0));
    // A multiple of ten in a..=b is a text a place shorter. The first step is taken by
    // selects (it is taken about every other time, and as a branch it mispredicted as
    // often); further steps are rare.
    let (a1, b1) = (a.div_ceil(10), b / 10);
    let shorter = a1 <= b1;
    // Masks, not `if`: the compiler made a select of the pair a branch.
    let keep = u64::from(shorter).wrapping_neg();
    let (mut a, mut b) = ((a1 & keep) | (a & !keep), (b1 & keep) | (b & !keep));
    let mut places = d0 - u32::from(shorter);
    // Where the first step was not taken, the same test fails again at once.
    while places > 0 && a.div_ceil(10) <= b / 10 {
        (a, b) = (a.div_ceil(10), b / 10);
        places -= 1;
    }
    if places == 0 {
        // Whole: the caller's.
        return None;
    }
    // The integer nearest |v| 10^places; exactly halfway, two texts tie.
    let scaled = 2 * m * POW10[places as usize];
    let (q, r) = (scaled >> shift, scaled & mask);
    let half = 1u64 << s;
    if r == half {
        return None;
    }
    let digits = q + u64::from(r > half);
    debug_assert!((a..=b).contains(&digits));
    Some((digits, places))
}

/// Whether `v` is whole (or zero, or not finite), or its exact decimal value has 10
/// significant digits or fewer: only then can it lie halfway between two shortest
/// texts, which are at most 9 digits for an f32.
fn may_tie(v: f32) -> bool {
    let bits = v.to_bits() & 0x7fff_ffff;
    let biased = (bits >> 23) as i32;
    if biased == 0 || biased == 0xff {
        return true;
    }
    // v = m 2^e with m odd, so its exact decimal value is m 5^-e / 10^-e: the digits of
    // m 5^-e, none of them trailing zeros.
    let mantissa = u64::from((bits & 0x7f_ffff) | 0x80_0000);
    let shift = mantissa.trailing_zeros() as i32;
    let (m, e) = (mantissa >> shift, biased - 150 + shift);
    if e >= 0 {
        return true;
    }
    // m < 2^24 and 5^14 < 2^33: no overflow.
    -e <= 14 && m * 5u64.pow((-e) as u32) < 10_000_000_000
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_are_written_as_display_writes_them() {
        let mut values = vec![0, 1, 9, 10, 99, 100, 255, 999, 1000, 120_484, u32::MAX];
        values.extend((0..32).map(|k| 1u32 << k));
        values.extend((1..10).map(|k| 10u32.pow(k) - 1));
        for v in values {
            let mut space = [0; ROW_MAX];
            let mut row = Row {
                bytes: &mut space,
                len: 0,
            };
            row.byte(b'x');
            row.uint(v);
            row.byte(b',');
            row.small_uint(v);
            assert_eq!(&row.bytes[..row.len], format!("x{v},{v}").as_bytes());
        }
        // Every value of the table.
        for v in 0..1000 {
            let mut space = [0; ROW_MAX];
            let mut row = Row {
                bytes: &mut space,
                len: 0,
            };
            row.small_uint(v);
            assert_eq!(&row.bytes[..row.len], v.to_string().as_bytes());
        }
    }

    #[test]
    fn floats_are_written_as_display_writes_them() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut floats = ryu::Buffer::new();
        let mut check = |v: f32| assert_displayed(&mut floats, v);
        for v in [
            0.0f32,
            -0.0,
            1.0,
            100.0,
            21.574419,
            1e-5,
            1e-7,
            1e16,
            3.4e38,
            3_136_939.2,
            -342_417.62,
            1.003_906_2,
            999_999.94,
            -25.0,
            16_777_215.0,
            16_777_216.0,
            -16_777_218.0,
            f32::MIN_POSITIVE,
            1e-45,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            check(v);
        }
        // Every bit pattern is a float: 300,000 drawn at random, and as many ranges.
        for _ in 0..300_000 {
            check(f32::from_bits(rng.random()));
            check(rng.random_range(0.0f32..300.0));
            check(rng.random_range(-1e7f32..1e7));
            // Few significant bits: where ties are.
            let bits = rng.random_range(1..=24);
            let m = rng.random_range(0..1u32 << bits) as f32;
            check(m / (1u64 << rng.random_range(0..40)) as f32);
            // Whole numbers, which are written as integers.
            check(rng.random_range(-20_000_000i32..20_000_000) as f32);
        }
    }

    /// Asserts that `Row::float` writes `v` as `Display` does.
    fn assert_displayed(floats: &mut ryu::Buffer, v: f32) {
        let mut space = [0; ROW_MAX];
        let mut row = Row {
            bytes: &mut space,
            len: 0,
        };
        row.float(floats, v);
        assert_eq!(&row.bytes[..row.len], v.to_string().as_bytes(), "{v:e}");
    }

    /// [`assert_displayed`] for the floats of the bit patterns `bits`; how many.
    fn floats_match_display(bits: impl Iterator<Item = u32>) -> usize {
        let mut floats = ryu::Buffer::new();
        let mut checked = 0;
        for b in bits {
            assert_displayed(&mut floats, f32::from_bits(b));
            checked += 1;
        }
        checked
    }

    #[test]
    fn the_shortest_fixed_texts_are_displays_over_their_span() {
        // [1/8, 2^20), both signs: every 997th bit pattern, and the first and last
        // hundred of each binade (the power-of-two mantissas and their neighbours).
        let (lo, hi) = (124u32 << 23, 147u32 << 23);
        let mut n = floats_match_display((lo..hi).step_by(997));
        n += floats_match_display((lo..hi).step_by(997).map(|b| b | 1 << 31));
        for e in 123..=147u32 {
            n += floats_match_display((e << 23).saturating_sub(100)..(e << 23) + 100);
        }
        assert!(n > 190_000);
        // The shortest texts found directly, not left to ryu: most of the span.
        let direct = (lo..hi)
            .step_by(997)
            .filter(|&b| shortest_fixed(f32::from_bits(b)).is_some());
        assert!(
            direct.count() > 190_000,
            "too few floats took the direct path"
        );
    }

    /// Every f32 of [1/8, 2^20): `cargo test --release -- --ignored every_f32` (about a
    /// minute).
    #[test]
    #[ignore = "190 million floats: run by hand after changing shortest_fixed"]
    fn every_f32_of_the_shortest_fixed_span_is_displays() {
        let n = floats_match_display((124u32 << 23)..(147u32 << 23));
        assert_eq!(n, 23 << 23);
    }

    #[test]
    fn fate_rows_are_those_of_the_format_string() {
        // Every field at its edges, and enough rows to cross the buffer's flush.
        let mut points = Vec::new();
        for i in 0..5_000u32 {
            points.push(ScanPoint {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                intensity: 0,
                ring: 0,
                point: if i % 13 == 0 { None } else { Some(i * 7919) },
                fate: (i % 6) as u8,
                cause: if i % 5 == 0 { 255 } else { (i % 4) as u8 },
                range_clean: match i % 4 {
                    0 => 0.0,
                    1 => 1e-7,
                    2 => 123.456_79,
                    _ => i as f32 * 0.013,
                },
                ground: (i % 2) as u8,
                cluster: if i % 3 == 0 { -1 } else { i as i32 * 31 },
            });
        }
        points.push(ScanPoint {
            point: Some(u32::MAX),
            cluster: i32::MIN,
            ..points[1]
        });
        let mut want = format!("{FATES_HEADER}\n");
        for p in &points {
            let point = p.point.map_or(-1, i64::from);
            want += &format!(
                "{point},{},{},{},{},{}\n",
                p.fate, p.cause, p.range_clean, p.ground, p.cluster
            );
        }
        let mut got = Vec::new();
        Fates { points: &points }.write_to(&mut got).unwrap();
        assert_eq!(String::from_utf8(got).unwrap(), want);
    }

    #[test]
    fn times_must_be_one_a_point() {
        let p = ScanPoint {
            x: 1.0,
            y: 2.0,
            z: 3.0,
            intensity: 4,
            ring: 5,
            point: Some(0),
            fate: 0,
            cause: 255,
            range_clean: 3.7,
            ground: 0,
            cluster: -1,
        };
        for format in [Format::Pcd, Format::Csv] {
            let scan = Scan {
                format,
                points: &[p, p],
                times: Some(&[0.5]),
            };
            let e = scan.write_to(&mut Vec::new()).unwrap_err();
            assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput, "{format:?}");
        }
    }

    #[test]
    fn point_indices_are_written_as_display_writes_them() {
        // Runs of consecutive indices (counted up) across every change in the number of
        // digits, gaps (written afresh), added echoes, and indices beyond the counted ones.
        let mut points: Vec<Option<u32>> = (0..1_100).map(Some).collect();
        for start in [
            9_990u32,
            99_990,
            999_990,
            9_999_990,
            99_999_990,
            999_999_990,
        ] {
            points.extend((start..start + 20).map(Some));
            points.push(None);
        }
        points.extend([
            Some(5),
            Some(7),
            Some(8),
            None,
            Some(9),
            Some(10),
            Some(100),
        ]);
        points.extend((u32::MAX - 3..=u32::MAX).map(Some));
        let rows: Vec<ScanPoint> = points
            .iter()
            .enumerate()
            .map(|(k, &point)| ScanPoint {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                intensity: 0,
                ring: 0,
                point,
                fate: (k % 9) as u8,
                cause: 255,
                range_clean: 12.5,
                ground: 0,
                cluster: -1,
            })
            .collect();
        let mut want = format!("{FATES_HEADER}\n");
        for p in &rows {
            let point = p.point.map_or(-1, i64::from);
            writeln!(want, "{point},{},255,12.5,0,-1", p.fate).unwrap();
        }
        let mut got = Vec::new();
        Fates { points: &rows }.write_to(&mut got).unwrap();
        assert_eq!(String::from_utf8(got).unwrap(), want);
    }

    #[test]
    fn one_pass_over_both_files_writes_what_each_writer_writes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // More rows than a chunk of either file holds, in a shuffled order.
        let rows: Vec<ScanPoint> = (0..10_000u32)
            .map(|i| ScanPoint {
                x: rng.random_range(-80.0..80.0),
                y: rng.random_range(-80.0..80.0),
                z: rng.random_range(-3.0..3.0),
                intensity: rng.random(),
                ring: rng.random_range(0..64),
                point: (i % 7 != 0).then_some(i),
                fate: rng.random_range(0..9),
                cause: rng.random(),
                range_clean: rng.random_range(0.0..120.0),
                ground: rng.random_range(0..2),
                cluster: rng.random_range(-1..300),
            })
            .collect();
        let mut order: Vec<u32> = (0..rows.len() as u32).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, rng.random_range(0..=i));
        }
        let ordered: Vec<ScanPoint> = order.iter().map(|&j| rows[j as usize]).collect();
        for format in [Format::Kitti, Format::NuScenes] {
            let (mut scan, mut fates) = (Vec::new(), Vec::new());
            let (mut scan_writes, mut fate_writes) = (0, 0);
            write_scan_and_fates::<()>(
                format,
                &rows,
                &order,
                &mut |b| {
                    scan_writes += 1;
                    scan.extend_from_slice(b);
                    Ok(())
                },
                &mut |b| {
                    fate_writes += 1;
                    fates.extend_from_slice(b);
                    Ok(())
                },
            )
            .expect("a fixed-record format")
            .unwrap();
            let mut want = Vec::new();
            Scan {
                format,
                points: &ordered,
                times: None,
            }
            .write_to(&mut want)
            .unwrap();
            assert!(scan == want, "{format:?}: the scan's bytes differ");
            want.clear();
            Fates { points: &ordered }.write_to(&mut want).unwrap();
            assert!(fates == want, "{format:?}: the fates' bytes differ");
            assert!(
                scan_writes > 1 && fate_writes > 1,
                "{format:?}: one chunk only"
            );
        }
        for format in [Format::Pcd, Format::Csv] {
            let mut none = |_: &[u8]| Ok::<(), ()>(());
            let mut also = |_: &[u8]| Ok::<(), ()>(());
            assert!(write_scan_and_fates(format, &rows, &order, &mut none, &mut also).is_none());
        }
    }
}
