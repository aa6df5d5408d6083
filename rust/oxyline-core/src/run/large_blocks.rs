//! The extension's allocator: every block of at least [`MAPPED_MIN_BYTES`] gets its own
//! anonymous mapping, handed back to the operating system when it is freed; smaller blocks
//! come from the system allocator as before.
//!
//! Why: a large run's setup (the steady start, the integrator's factorisation, the species'
//! state, the first output row) allocates and frees vectors of a few MB to a few hundred MB.
//! glibc maps such a block on its own only until the first one is freed: its dynamic mmap
//! threshold then rises to that block's size (up to 32 MiB), so the later multi-MB vectors
//! come from its heaps, and their freed pages stay resident under the live blocks allocated
//! after them. At 1.05 M segments with O2 that was ~70 B per segment of the run's peak
//! resident set (the same run with `MALLOC_MMAP_THRESHOLD_=1048576` peaked that much lower).
//! The environment variable (or `mallopt`) is process-wide: it would change every allocation
//! of the user's process, numpy's included, and cannot be undone. This allocator does the
//! same for the core's own blocks only (`#[global_allocator]` of this library: Python and
//! numpy keep their allocators).
//!
//! A mapping is zero-filled by the kernel, so a zeroed allocation (`vec![0.0; n]`) costs no
//! page until it is written; growing a mapped vector moves its pages (`mremap`) instead of
//! copying them. The steps allocate no block this large (their scratch lives for the run), so
//! the page faults of fresh mappings are paid in the setup and at the output rows only.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks of at least this many bytes get their own mapping (glibc's own threshold before it
/// adapts is 128 KiB; 1 MiB keeps the mapping calls to the large vectors of large runs).
pub const MAPPED_MIN_BYTES: usize = 1 << 20;

/// The system allocator, with blocks of [`MAPPED_MIN_BYTES`] or more mapped on their own.
pub struct LargeBlocksMapped;

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod sys {
    use std::ffi::{c_int, c_void};

    unsafe extern "C" {
        fn mmap(
            addr: *mut c_void,
            len: usize,
            prot: c_int,
            flags: c_int,
            fd: c_int,
            off: i64,
        ) -> *mut c_void;
        fn munmap(addr: *mut c_void, len: usize) -> c_int;
        fn mremap(
            old: *mut c_void,
            old_len: usize,
            new_len: usize,
            flags: c_int,
            ...
        ) -> *mut c_void;
    }
    // Linux's values (the same on x86_64 and aarch64)
    const PROT_READ_WRITE: c_int = 0x1 | 0x2;
    const MAP_PRIVATE_ANONYMOUS: c_int = 0x02 | 0x20;
    const MREMAP_MAYMOVE: c_int = 1;
    const MAP_FAILED: *mut c_void = !0usize as *mut c_void;
    /// Mappings are page-aligned; a layout asking for more goes to the system allocator.
    pub const PAGE: usize = 4096;

    /// A fresh zero-filled mapping of `len` bytes, or null.
    pub unsafe fn map(len: usize) -> *mut u8 {
        // SAFETY: an anonymous private mapping at an address of the kernel's choosing
        let p = unsafe {
            mmap(
                std::ptr::null_mut(),
                len,
                PROT_READ_WRITE,
                MAP_PRIVATE_ANONYMOUS,
                -1,
                0,
            )
        };
        if p == MAP_FAILED {
            std::ptr::null_mut()
        } else {
            p.cast()
        }
    }

    /// Unmap a block made by [`map`] or [`remap`] with its length.
    pub unsafe fn unmap(p: *mut u8, len: usize) {
        // SAFETY: (p, len) is a whole mapping of ours, no longer used
        unsafe { munmap(p.cast(), len) };
    }

    /// Resize a mapping, moving its pages if needed (no copy); null on failure (the old
    /// mapping then stays as it was).
    pub unsafe fn remap(p: *mut u8, old: usize, new: usize) -> *mut u8 {
        // SAFETY: (p, old) is a whole mapping of ours
        let q = unsafe { mremap(p.cast(), old, new, MREMAP_MAYMOVE) };
        if q == MAP_FAILED {
            std::ptr::null_mut()
        } else {
            q.cast()
        }
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
impl LargeBlocksMapped {
    fn mapped(l: &Layout) -> bool {
        l.size() >= MAPPED_MIN_BYTES && l.align() <= sys::PAGE
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
// SAFETY: every block is freed by the allocator that made it: the size (fixed by the layout
// the caller passes back) decides mapped or not, the same way at allocation and at free.
unsafe impl GlobalAlloc for LargeBlocksMapped {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if Self::mapped(&l) {
            unsafe { sys::map(l.size()) }
        } else {
            unsafe { System.alloc(l) }
        }
    }

    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        if Self::mapped(&l) {
            // a fresh mapping is zero-filled
            unsafe { sys::map(l.size()) }
        } else {
            unsafe { System.alloc_zeroed(l) }
        }
    }

    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        if Self::mapped(&l) {
            unsafe { sys::unmap(p, l.size()) }
        } else {
            unsafe { System.dealloc(p, l) }
        }
    }

    unsafe fn realloc(&self, p: *mut u8, l: Layout, new_size: usize) -> *mut u8 {
        // SAFETY (of the layout): the caller guarantees new_size rounded to l.align() fits
        let new = unsafe { Layout::from_size_align_unchecked(new_size, l.align()) };
        match (Self::mapped(&l), Self::mapped(&new)) {
            (true, true) => unsafe { sys::remap(p, l.size(), new_size) },
            (false, false) => unsafe { System.realloc(p, l, new_size) },
            // across the threshold: a new block, the kept bytes copied, the old one freed
            _ => unsafe {
                let q = self.alloc(new);
                if !q.is_null() {
                    std::ptr::copy_nonoverlapping(p, q, l.size().min(new_size));
                    self.dealloc(p, l);
                }
                q
            },
        }
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
// SAFETY: the system allocator unchanged
unsafe impl GlobalAlloc for LargeBlocksMapped {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        unsafe { System.alloc(l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new_size: usize) -> *mut u8 {
        unsafe { System.realloc(p, l, new_size) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fill `len` bytes at `p` with a pattern of their index.
    unsafe fn fill(p: *mut u8, len: usize) {
        for i in 0..len {
            unsafe { *p.add(i) = (i % 251) as u8 };
        }
    }

    /// Whether the first `len` bytes at `p` still hold the pattern of [`fill`].
    unsafe fn holds(p: *const u8, len: usize) -> bool {
        (0..len).all(|i| unsafe { *p.add(i) } == (i % 251) as u8)
    }

    /// A block keeps its bytes through every kind of resize: mapped → larger mapped (moved
    /// pages), mapped → below the threshold (copied to the system allocator), and back.
    #[test]
    fn resizing_across_the_threshold_keeps_the_bytes() {
        let a = LargeBlocksMapped;
        let big = MAPPED_MIN_BYTES + 12_345;
        let l = Layout::from_size_align(big, 8).unwrap();
        unsafe {
            let p = a.alloc(l);
            assert!(!p.is_null());
            fill(p, big);
            let grown = 4 * MAPPED_MIN_BYTES;
            let p = a.realloc(p, l, grown);
            assert!(!p.is_null() && holds(p, big));
            let small = MAPPED_MIN_BYTES / 3;
            let p = a.realloc(p, Layout::from_size_align(grown, 8).unwrap(), small);
            assert!(!p.is_null() && holds(p, small));
            let p = a.realloc(p, Layout::from_size_align(small, 8).unwrap(), big);
            assert!(!p.is_null() && holds(p, small));
            fill(p, big);
            assert!(holds(p, big));
            a.dealloc(p, l);
        }
    }

    /// A zeroed block reads zero whichever allocator serves it, and an alignment beyond a
    /// page (which a mapping does not promise) is met by the system allocator.
    #[test]
    fn zeroed_and_over_aligned_blocks() {
        let a = LargeBlocksMapped;
        for (size, align) in [
            (2 * MAPPED_MIN_BYTES, 8),
            (1000, 8),
            (MAPPED_MIN_BYTES, 1 << 16),
        ] {
            let l = Layout::from_size_align(size, align).unwrap();
            unsafe {
                let p = a.alloc_zeroed(l);
                assert!(!p.is_null());
                assert_eq!(p as usize % align, 0, "size {size} align {align}");
                assert!((0..size).all(|i| *p.add(i) == 0));
                a.dealloc(p, l);
            }
        }
    }

    /// A vector grown element by element through the threshold (the pattern of a large run's
    /// output rows) keeps every element.
    #[test]
    fn a_vector_grown_through_the_threshold() {
        // the global allocator of this test binary is the system's: drive ours through a
        // Vec-like doubling by hand
        let a = LargeBlocksMapped;
        let mut cap = 1024usize;
        let mut p = unsafe { a.alloc(Layout::array::<u64>(cap).unwrap()) } as *mut u64;
        for i in 0..(1usize << 19) {
            if i == cap {
                let old = Layout::array::<u64>(cap).unwrap();
                cap *= 2;
                p = unsafe { a.realloc(p.cast(), old, cap * 8) }.cast();
                assert!(!p.is_null());
            }
            unsafe { *p.add(i) = i as u64 * 3 };
        }
        assert!((0..(1usize << 19)).all(|i| unsafe { *p.add(i) } == i as u64 * 3));
        unsafe { a.dealloc(p.cast(), Layout::array::<u64>(cap).unwrap()) };
    }
}
