//! Process-wide memory settings of the binary.

/// Opts this process out of transparent huge pages (Linux; elsewhere nothing).
///
/// Why: with huge pages every first touch of heap memory faults in and clears 2 MB.
/// Where the kernel takes huge pages from memory it has handed back to the host (a VM
/// with free page reporting, as on the machine this tool is measured on), each such
/// fault also waits for the host: `run` on the shared capture, started after two idle
/// seconds, took 122-137 ms (median) instead of 72-78 ms with 4 KB pages. Started back
/// to back, huge pages were faster by up to 6 %; the opt-out trades that for run times
/// that do not depend on the host's memory (README, "Benchmarks"). mimalloc is built
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
    #[cfg(target_os = "linux")]
    {
        const PAGE: usize = 4096;
        let spare = v.spare_capacity_mut();
        let bytes = len.min(spare.len()) * std::mem::size_of::<T>();
        let start = spare.as_mut_ptr() as usize;
        // Whole pages inside the spare capacity only.
        let (a, b) = (
            (start + PAGE - 1) & !(PAGE - 1),
            (start + bytes) & !(PAGE - 1),
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
    let _ = (v, len);
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
