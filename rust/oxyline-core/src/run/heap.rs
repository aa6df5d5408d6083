//! Freed heap pages handed back to the operating system once a large pass's output begins
//! (the 1.05 M-segment O2 cycle's peak resident set).
//!
//! The setup of a pass (the steady state, the first pass of a transport run, the integrator's
//! factors, the closures' per-vessel work) and its first steps and observations allocate and
//! free hundreds of MB in pieces of a few MB. glibc's allocator keeps such freed memory in its
//! heaps (its dynamic mmap threshold rises after the first large free, so later multi-MB
//! vectors come from the heaps too) and returns only what lies at a heap's top. The output
//! table, reserved in one allocation of its final size, fills page by page and cannot reuse
//! those freed pages: they stayed resident under it to the run's peak, ~40 MiB of a
//! 262 k-segment O2 run's (measured with benches/profile_memory.py).
//! `malloc_trim` returns every whole free page of every arena (`MADV_DONTNEED`; the
//! allocator's bookkeeping stays). The cycle loop calls it once per pass, after the pass's
//! first output row past its start (`Cycles::step`): calling it before the loop missed the
//! first steps' scratch (16 instead of 41 MiB at 262 k segments), calling it again later
//! released nothing more.
//!
//! A large run's peak resident set is reached while it sets up, before that first row (at
//! 1.05 M segments with O2: ~1,190 B per segment against ~1,020–1,050 through the steps), and
//! ~70 B per segment of it are freed pages (glibc told to map every block of 1 MiB or more
//! on its own peaks that much lower). The pass also hands the free pages back at its start,
//! after the steady start and after its one factorisation (`run::pass`); measured, that did
//! not lower the 1.05 M-segment peak (1,186 against 1,187 B per segment): the pages that
//! count are freed and allocated again inside one stage, not between them. The Python
//! extension's allocator (`run::large_blocks`) now maps each block of 1 MiB or more
//! on its own and unmaps it when freed, which removed them (peak 1,109 B per segment); the
//! trims still serve the smaller blocks and other hosts of the core.
//!
//! It is made only for circuits of at least [`RELEASE_MIN_UNKNOWNS`] unknowns: it walks the
//! allocator's heaps under their locks, which a small run (thousands of them in an ensemble's
//! threads) should not pay for what it would not gain.

/// Circuits with fewer unknowns do not release (≈ 20 000 segments of a tree).
pub const RELEASE_MIN_UNKNOWNS: usize = 1 << 16;

/// Return the allocator's free pages to the operating system if the circuit has at least
/// [`RELEASE_MIN_UNKNOWNS`] unknowns (glibc only; elsewhere nothing). Values and results are
/// untouched: only pages no live allocation uses are released.
pub fn release_free_pages(unknowns: usize) {
    if unknowns >= RELEASE_MIN_UNKNOWNS {
        trim();
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn trim() {
    unsafe extern "C" {
        /// glibc: release free memory from the heaps, keeping `pad` bytes at the main heap's
        /// top; returns 1 if memory was released.
        fn malloc_trim(pad: usize) -> std::ffi::c_int;
    }
    // SAFETY: malloc_trim takes no pointers and only releases pages the allocator owns and no
    // allocation uses; it is thread-safe (it locks each arena in turn).
    unsafe {
        malloc_trim(0);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim() {}

#[cfg(all(test, target_os = "linux", target_env = "gnu"))]
mod tests {
    use super::*;

    /// Resident bytes of this process (VmRSS).
    fn resident() -> f64 {
        let s = std::fs::read_to_string("/proc/self/status").unwrap();
        s.lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap()
            * 1024.0
    }

    #[test]
    fn freed_heap_pages_below_a_live_block_are_given_back() {
        // a freed 8 MiB mmapped block raises glibc's dynamic mmap threshold above 1 MiB, so
        // the 1 MiB blocks below come from the heap, as a large run's multi-MB vectors do
        drop(std::hint::black_box(vec![1u8; 8 << 20]));
        let mut blocks: Vec<Vec<u8>> = (0..192).map(|i| vec![i as u8 | 1; 1 << 20]).collect();
        // a live block on top: the freed ones are not at the heap's top, so free() alone
        // keeps them resident (the situation of the output table over the setup's garbage)
        let top = std::hint::black_box(vec![7u8; 1 << 20]);
        blocks.clear();
        blocks.shrink_to_fit();
        let before = resident();
        release_free_pages(RELEASE_MIN_UNKNOWNS);
        let after = resident();
        assert_eq!(top[12345], 7);
        // 192 MiB were freed; other tests of this process allocate too, so ask for half
        assert!(
            before - after > 96.0 * 1048576.0,
            "released {:.0} MiB",
            (before - after) / 1048576.0
        );
    }
}
