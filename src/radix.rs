//! Stable LSD radix sort of packed `u64` keys: the voxel keys of the grid clustering and
//! the shared firing slots of a point cloud's returns, each with an ascending index in its
//! low bits. Written here rather than taken from `radsort` (which would sort them too,
//! stably): its digits are bytes, where this spreads the key's width over as few digits of
//! at most 11 bits as it needs (the clustering's 29-bit keys in three passes, not four; a
//! KITTI scan's 18-bit slots in two, not three).

/// Bits per radix-sort digit (a 2048-entry histogram stays in L1).
pub(crate) const RADIX_BITS: u32 = 11;

/// Stable LSD radix sort of `items` by their bits `from..from + bits` (the low bits carry
/// a point index, already ascending, so equal keys keep input order). All digit
/// histograms come from one read pass, and the digit width is spread evenly over the
/// passes (29 key bits: three passes of 10 bits, not 11 + 11 + 7).
pub(crate) fn sort_packed(items: &mut Vec<u64>, from: u32, bits: u32) {
    const MAX_PASSES: usize = 6;
    let n = items.len();
    let passes = bits.div_ceil(RADIX_BITS).max(1) as usize;
    debug_assert!(passes <= MAX_PASSES);
    let digit = bits.div_ceil(passes as u32);
    let buckets = 1usize << digit;
    let mask = (buckets - 1) as u64;
    let mut hist = vec![0u32; buckets * passes];
    for &k in items.iter() {
        for (p, h) in hist.chunks_exact_mut(buckets).enumerate() {
            h[((k >> (from + p as u32 * digit)) & mask) as usize] += 1;
        }
    }
    let mut tmp = vec![0u64; n];
    for (p, h) in hist.chunks_exact_mut(buckets).enumerate() {
        // A digit shared by every item leaves the order unchanged.
        if h.contains(&(n as u32)) {
            continue;
        }
        let mut sum = 0;
        for c in h.iter_mut() {
            let v = *c;
            *c = sum;
            sum += v;
        }
        let shift = from + p as u32 * digit;
        for &k in items.iter() {
            let d = ((k >> shift) & mask) as usize;
            tmp[h[d] as usize] = k;
            h[d] += 1;
        }
        std::mem::swap(items, &mut tmp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_radix_sort_sorts_by_key_bits_and_keeps_index_order() {
        for (bits, ib) in [(40u32, 13u32), (7, 13), (29, 15), (1, 1)] {
            let n = 1u64 << (ib - 1).min(12);
            let mut items: Vec<u64> = (0..n)
                .map(|i| ((i * 2_654_435_761) % (1 << bits)) << ib | i)
                .collect();
            let orig = items.clone();
            sort_packed(&mut items, ib, bits);
            // Sorted by (key, index): the key order, and input order among equal keys.
            let mut expected = orig;
            expected.sort_unstable();
            assert_eq!(items, expected, "bits {bits}");
        }
    }
}
