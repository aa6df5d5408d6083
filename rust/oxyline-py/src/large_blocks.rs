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
