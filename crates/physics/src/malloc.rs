//! glibc's malloc tuned for topology changes: its fast bins off.

/// Turns glibc malloc's fast bins off in this process (`mallopt(M_MXFAST, 0)`, what
/// `GLIBC_TUNABLES=glibc.malloc.mxfast=0` does), unless the environment's `GLIBC_TUNABLES`
/// sets `mxfast` itself. Returns whether it did (always `false` elsewhere than Linux with
/// glibc, where nothing is done). The Python extension calls it when it is imported; a Rust
/// program may.
///
/// Why: a set-up or a topology change frees millions of small vectors (matches, rows) and
/// then asks for a large one; glibc then consolidates every freed fast-bin block inside that
/// request, which made some first cuts at 10^5 tets 25 ms slower (a plane cut of 1,300
/// faces: 54.5 ms instead of 28-30 in one of three runs; 17 ms of consolidation in a
/// profile). With the fast bins off the cut stayed at 28-30 ms in three runs, and the
/// set-up and first step of a cloth of 10^6 quads took 13.2-14.3 s against 12.9-13.1 s with
/// them (mimalloc, tried as the global allocator instead, removed the stall too but took
/// 15.1-16.7 s for that set-up). Measured on 2026-12-05 on a 2-vCPU AMD EPYC.
pub fn tune_malloc() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        if std::env::var("GLIBC_TUNABLES").is_ok_and(|t| sets_mxfast(&t)) {
            return false;
        }
        // SAFETY: `mallopt` takes two integers by value and sets a parameter of the
        // allocator under the allocator's own lock; glibc documents `M_MXFAST` = 1 with a
        // value of 0 as turning the fast bins off (mallopt(3): "Setting M_MXFAST to 0
        // disables the use of fastbins"), at any time and from any thread: blocks already
        // in fast bins stay valid and are consolidated by the next large request. No
        // pointer is passed, nothing is read or written by us: no memory-safety condition.
        // Exercised by `tests::tune_malloc_turns_the_fast_bins_off` and by every import
        // of the Python extension.
        #[allow(unsafe_code)]
        let set = unsafe { libc::mallopt(libc::M_MXFAST, 0) };
        set == 1
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// Whether a `GLIBC_TUNABLES` value sets `glibc.malloc.mxfast` (its entries are
/// `name=value`, separated by colons).
#[cfg_attr(not(all(target_os = "linux", target_env = "gnu")), allow(dead_code))]
fn sets_mxfast(tunables: &str) -> bool {
    tunables.split(':').any(|e| {
        e.split_once('=')
            .is_some_and(|(k, _)| k == "glibc.malloc.mxfast")
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn only_an_mxfast_entry_counts() {
        use super::sets_mxfast;
        assert!(sets_mxfast("glibc.malloc.mxfast=0"));
        assert!(sets_mxfast("glibc.malloc.check=3:glibc.malloc.mxfast=64"));
        assert!(!sets_mxfast("glibc.malloc.mxfastx=1"));
        assert!(!sets_mxfast("glibc.malloc.mxfast"));
        assert!(!sets_mxfast("glibc.malloc.check=3"));
    }

    /// On glibc (unless the environment tunes `mxfast`) the call succeeds, and allocating
    /// and freeing afterwards works as before; elsewhere it reports that it did nothing.
    #[test]
    fn tune_malloc_turns_the_fast_bins_off() {
        let tuned_by_env = std::env::var("GLIBC_TUNABLES").is_ok_and(|t| super::sets_mxfast(&t));
        let done = super::tune_malloc();
        if cfg!(all(target_os = "linux", target_env = "gnu")) && !tuned_by_env {
            assert!(done, "mallopt(M_MXFAST, 0) refused");
        } else {
            assert!(!done);
        }
        // small blocks freed, then a large request (what consolidated before)
        let small: Vec<Vec<u32>> = (0..10_000).map(|k| vec![k; 4]).collect();
        let sum: u64 = small.iter().map(|v| u64::from(v[0])).sum();
        drop(small);
        let large = vec![1u8; 1 << 22];
        assert_eq!(sum, (0..10_000u64).sum());
        assert_eq!(large.iter().map(|&b| u64::from(b)).sum::<u64>(), 1 << 22);
    }
}
