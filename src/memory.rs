//! Process-wide memory settings of the binary.

/// Opts this process out of transparent huge pages (Linux; elsewhere nothing).
///
/// Why: with huge pages every first touch of heap memory faults in and clears 2 MB.
/// Where the kernel takes huge pages from memory it has handed back to the host (a VM
/// with free page reporting, as on the machine this tool is measured on), each such
/// fault also waits for the host, and a run started after an idle pause took far longer
/// than with 4 KB pages. Back to back, huge pages were a little faster; the opt-out
/// trades that for run times that do not depend on the host's memory (figures in the
/// manual, "Benchmark history", "Huge pages"). mimalloc is built
/// without its own request for them (its `no_thp` feature: it used to `madvise` its
/// whole arena); this covers kernels whose policy gives them to every process.
pub fn no_transparent_huge_pages() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_THP_DISABLE only sets a flag of this process and reads no memory of
    // ours. A kernel without it returns an error, which leaves huge pages as they were.
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0);
    }
}

/// Faults in the pages of the first `len` elements of a vector's spare capacity.
///
/// Why: a first touch costs a page fault per 4 KB page (about 1.15 us each on the
/// machine this tool is measured on); `madvise(MADV_POPULATE_WRITE)` takes the same
/// pages in one call at about 0.8 us each. Worth it only for large buffers that are
/// about to be filled; the contents are unchanged (Linux 5.14 on; elsewhere, or on an
/// error, nothing happens and the pages fault in as they are written).
pub fn prefault<T>(v: &mut Vec<T>, len: usize) {
    let bytes = len.min(v.capacity() - v.len()) * std::mem::size_of::<T>();
    populate_spare(v, 0, bytes);
}

/// Faults in bytes `from..from + bytes` of a vector's spare capacity (whole pages inside
/// it only), as [`prefault`] does.
fn populate_spare<T>(v: &mut Vec<T>, from: usize, bytes: usize) {
    #[cfg(target_os = "linux")]
    {
        const PAGE: usize = 4096;
        let spare = v.spare_capacity_mut();
        let spare_bytes = std::mem::size_of_val(spare);
        let end = from.saturating_add(bytes).min(spare_bytes);
        let from = from.min(end);
        let start = spare.as_mut_ptr() as usize;
        // Whole pages inside the spare capacity only.
        let (a, b) = (
            (start + from + PAGE - 1) & !(PAGE - 1),
            (start + end) & !(PAGE - 1),
        );
        if b > a {
            // SAFETY: [a, b) lies inside the vector's allocation, past its initialised
            // elements; MADV_POPULATE_WRITE maps those pages without changing what they
            // hold, and they hold nothing the vector has initialised.
            unsafe {
                libc::madvise(a as *mut libc::c_void, b - a, libc::MADV_POPULATE_WRITE);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (v, from, bytes);
}

/// Bytes of heap each frame worker of `run` faults in while it waits for its first frame
/// (see [`HeapWarmer`]); 0, the default, turns the warm-up off.
static WORKER_WARMUP_BYTES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Lets each frame worker of `run` fault in `bytes` of its heap while it waits for its
/// first frame (see [`HeapWarmer`]). The binary turns it on: it relies on mimalloc giving
/// a thread's freed block back to that thread's next allocations, which the system
/// allocator does not do for blocks this large (it unmaps them).
pub fn warm_worker_heaps(bytes: usize) {
    WORKER_WARMUP_BYTES.store(bytes, std::sync::atomic::Ordering::Relaxed);
}

/// The bytes set by [`warm_worker_heaps`] (0 unless the binary set them).
pub fn worker_warmup_bytes() -> usize {
    WORKER_WARMUP_BYTES.load(std::sync::atomic::Ordering::Relaxed)
}

/// A block of a thread's heap faulted in a slice at a time while the thread has nothing
/// else to do; dropped, it hands its pages back to the thread's heap, whose next
/// allocations find them mapped.
///
/// Why: a worker's heap grows to about 10 MB over a capture's frames, and every first
/// touch of a page costs a fault in the worker's time, while at start-up the workers wait
/// for their first frames as the calling thread decodes. Faulted in then, in slices of
/// [`HeapWarmer::SLICE`] bytes with `MADV_POPULATE_WRITE`, the pages cost the run next to
/// nothing (figures in the manual, "Benchmark history", "Warm worker heaps"). The block
/// stays below mimalloc's largest in-segment block (16 MiB): a larger one would be mapped
/// apart and unmapped when freed.
pub struct HeapWarmer {
    block: Vec<u8>,
    done: usize,
}

impl HeapWarmer {
    /// Bytes faulted in per [`HeapWarmer::step`]: the longest a ready frame waits for a
    /// warming worker is one slice's faults.
    pub const SLICE: usize = 1 << 20;

    /// A warmer of `bytes` (`None` for 0, and where pages cannot be populated).
    pub fn new(bytes: usize) -> Option<HeapWarmer> {
        (bytes > 0 && cfg!(target_os = "linux")).then(|| HeapWarmer {
            block: Vec::with_capacity(bytes),
            done: 0,
        })
    }

    /// Faults in the next slice; false once the whole block is in.
    pub fn step(&mut self) -> bool {
        let total = self.block.capacity();
        if self.done >= total {
            return false;
        }
        let bytes = Self::SLICE.min(total - self.done);
        populate_spare(&mut self.block, self.done, bytes);
        self.done += bytes;
        self.done < total
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn thp_enabled() -> Option<String> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        status
            .lines()
            .find_map(|l| l.strip_prefix("THP_enabled:"))
            .map(|v| v.trim().to_string())
    }

    #[test]
    fn prefault_keeps_the_contents_and_faults_in_the_pages() {
        let minor = || {
            // SAFETY: getrusage writes into the struct it is given.
            let mut u: libc::rusage = unsafe { std::mem::zeroed() };
            unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut u) };
            u.ru_minflt
        };
        // With huge pages the 8 MB would fault in four pieces anyway.
        no_transparent_huge_pages();
        let mut v: Vec<u64> = Vec::with_capacity(1 << 20);
        v.extend([7, 8, 9]);
        prefault(&mut v, 1 << 20);
        assert_eq!(v, [7, 8, 9]);
        // Writing the 8 MB now takes (almost) no page fault: they were taken above.
        let before = minor();
        v.resize(1 << 20, 1);
        let faults = minor() - before;
        assert!(faults < 64, "{faults} faults after prefault");
        assert!(v[3..].iter().all(|&x| x == 1));
        // Too long a length stays inside the capacity; zero does nothing.
        let mut w: Vec<u8> = Vec::with_capacity(10);
        prefault(&mut w, 1 << 30);
        prefault(&mut w, 0);
        w.push(1);
        assert_eq!(w, [1]);
    }

    /// Slices of a warmer cover its block once and then stop; a populated range takes
    /// (almost) no page fault when written, the rest of the spare capacity does.
    #[test]
    fn heap_warmer_populates_its_block_a_slice_at_a_time() {
        assert!(HeapWarmer::new(0).is_none());
        let mut w = HeapWarmer::new(3 * HeapWarmer::SLICE + 100).expect("Linux");
        let steps: Vec<bool> = std::iter::from_fn(|| Some(w.step())).take(6).collect();
        assert_eq!(steps, [true, true, true, false, false, false]);
        assert_eq!(w.done, w.block.capacity());

        let minor = || {
            // SAFETY: getrusage writes into the struct it is given.
            let mut u: libc::rusage = unsafe { std::mem::zeroed() };
            unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut u) };
            u.ru_minflt
        };
        no_transparent_huge_pages();
        // 16 MB: the second half populated, then each half written.
        let half = 8 << 20;
        let mut v: Vec<u8> = Vec::with_capacity(2 * half);
        populate_spare(&mut v, half, half);
        let before = minor();
        v.resize(half, 1);
        let first = minor() - before;
        let before = minor();
        v.resize(2 * half, 2);
        let second = minor() - before;
        assert!(first >= 1024, "{first} faults in the half left out");
        assert!(second < 64, "{second} faults in the populated half");
        assert!(v[..half].iter().all(|&x| x == 1) && v[half..].iter().all(|&x| x == 2));
    }

    #[test]
    fn the_process_opts_out_of_huge_pages() {
        // Kernels before 6.0 do not report the flag: nothing to check there.
        let Some(before) = thp_enabled() else {
            eprintln!("SKIPPED: /proc/self/status has no THP_enabled line (kernel < 6.0)");
            return;
        };
        no_transparent_huge_pages();
        assert_eq!(thp_enabled().as_deref(), Some("0"), "was {before}");
    }
}
