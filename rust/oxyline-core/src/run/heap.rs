//! Freed heap pages handed back to the operating system before a large run's cycle loop
//! (issue 9 item 6: the 1.05 M-segment O2 cycle's peak resident set).
//!
//! The setup of a pass (the steady state, the first pass of a transport run, the integrator's
//! factors, the closures' per-vessel work) allocates and frees hundreds of MB in pieces of a few
//! MB. glibc's allocator keeps such freed memory in its heaps (its dynamic mmap threshold rises
//! after the first large free, so later multi-MB vectors come from the heap too) and returns
//! only what lies at a heap's top. The cycle loop then grows the output table in one
//! allocation of its own, which cannot reuse those freed pages: they stayed resident under the
//! output, ~180 B per segment of a 262 k-segment O2 run's peak (benches/results.md, "1.05 M
//! peak memory (session 12, helper mem)"). `malloc_trim` returns every whole free page of every
//! arena (the pages are unmapped with `MADV_DONTNEED`; the allocator's bookkeeping stays).
//!
//! It is one call per pass, made only for circuits of at least [`RELEASE_MIN_UNKNOWNS`]
//! unknowns: it walks the allocator's heaps under their locks, which a small run (thousands of
//! them in an ensemble's threads) should not pay for what it would not gain.

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
