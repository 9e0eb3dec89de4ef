//! Process-wide memory settings of the binary.

/// Opts this process out of transparent huge pages (Linux; elsewhere nothing).
///
/// Why: the binary's allocator, mimalloc, asks for huge pages on its whole arena
/// (`madvise(MADV_HUGEPAGE)`), so every first touch of heap memory faults in and clears
/// 2 MB. Where the kernel takes huge pages from memory it has handed back to the host (a
/// VM with free page reporting, as on the machine this tool is measured on), each such
/// fault also waits for the host: `run` on the shared capture, started after two idle
/// seconds, took 122-137 ms (median) instead of 72-78 ms with 4 KB pages. Started back
/// to back, huge pages were faster by up to 6 %; the opt-out trades that for run times
/// that do not depend on the host's memory (README, "Benchmarks").
pub fn no_transparent_huge_pages() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_THP_DISABLE only sets a flag of this process and reads no memory of
    // ours. A kernel without it returns an error, which leaves huge pages as they were.
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0);
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
