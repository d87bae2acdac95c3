//! Transparent huge pages for the hot traversal arrays.
//!
//! Traversal is bound by memory latency: every node and triangle visit is a
//! likely cache miss, and with 4 KiB pages most of them also miss the TLB
//! (the BVH and triangles of a 350k-triangle car span ~30 MiB, the TLB reaches
//! ~6 MiB). Backing the arrays with 2 MiB pages removes the page walks. The
//! kernel here has THP in `madvise` mode, so we ask for it per allocation,
//! before the pages are first touched.

/// Copies `data` into a fresh allocation advised for huge pages (Linux; a
/// plain copy elsewhere, or when `PRTBAKE_NO_HUGEPAGES` is set).
pub fn copy_to_huge_pages<T: Copy>(data: &[T]) -> Vec<T> {
    let mut out = reserve_huge(data.len());
    out.extend_from_slice(data);
    out
}

/// An empty vector with room for `capacity` elements, advised for huge pages.
pub fn reserve_huge<T>(capacity: usize) -> Vec<T> {
    let out: Vec<T> = Vec::with_capacity(capacity);
    advise_huge(out.as_ptr() as usize, capacity * std::mem::size_of::<T>());
    out
}

/// A zeroed (`T::default()`) vector of `len` elements advised for huge
/// pages, for large arrays read at random (the bounces' gather rows).
pub fn filled_huge<T: Copy + Default>(len: usize) -> Vec<T> {
    let mut out = reserve_huge(len);
    out.resize(len, T::default());
    out
}

#[cfg(target_os = "linux")]
fn advise_huge(address: usize, bytes: usize) {
    const HUGE: usize = 2 << 20;
    if bytes < HUGE || std::env::var_os("PRTBAKE_NO_HUGEPAGES").is_some() {
        return;
    }
    // Only whole 2 MiB extents inside the allocation can become huge pages.
    let start = address.next_multiple_of(HUGE);
    let end = (address + bytes) / HUGE * HUGE;
    if end > start {
        // SAFETY: madvise only changes paging advice for a range inside an
        // allocation we own; it does not read or write the memory.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge(_address: usize, _bytes: usize) {}
