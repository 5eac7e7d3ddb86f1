//! Large output buffers backed by huge pages where the system allows it.
//!
//! A polygonizer's output (vertices, normals, triangles) is fresh memory on every call; at 256³
//! it is tens of megabytes, and faulting it in one 4 KiB page at a time took a tenth to a
//! sixth of a run here (perf, 256³ blobs). On Linux with transparent huge pages in `madvise` mode, asking for huge pages
//! before the first write makes it one fault per 2 MiB. Elsewhere this does nothing, and the
//! environment variable `IMPLICITMESH_NO_HUGEPAGES` (set at all) turns it off.

/// An empty vector with room for `n` elements, whose pages are advised to be huge pages when
/// it is large (at least 4 MiB). The pages are not touched here.
pub fn with_capacity_huge<T>(n: usize) -> Vec<T> {
    advise_huge(Vec::with_capacity(n))
}

/// [`with_capacity_huge`] for room that is only an optimisation (address space reserved so
/// that a vector never grows by copying): where the system refuses the reservation (strict
/// overcommit), an empty vector that grows as usual.
pub fn reserve_huge<T>(n: usize) -> Vec<T> {
    let mut v: Vec<T> = Vec::new();
    if v.try_reserve_exact(n).is_err() {
        return Vec::new();
    }
    advise_huge(v)
}

/// Advises huge pages for the spare capacity of `v` when it is large (at least 4 MiB).
fn advise_huge<T>(v: Vec<T>) -> Vec<T> {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
        static OFF: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        let off = *OFF.get_or_init(|| std::env::var_os("IMPLICITMESH_NO_HUGEPAGES").is_some());
        if bytes >= 2 * HUGE && !off {
            let start = v.as_ptr() as usize;
            let lo = start.next_multiple_of(HUGE);
            let hi = (start + bytes) / HUGE * HUGE;
            if hi > lo {
                // SAFETY: [lo, hi) lies inside the vector's allocation (page-aligned, as madvise
                // requires); MADV_HUGEPAGE only changes how the kernel backs those pages and
                // never their contents. A failure (no THP support) is harmless and ignored.
                unsafe {
                    libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
                }
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refused_reservation_gives_an_empty_vector() {
        // Far beyond any address space: refused, not an abort; the vector still grows.
        let mut v: Vec<u64> = reserve_huge(usize::MAX / 16);
        assert_eq!(v.capacity(), 0);
        v.push(7);
        assert_eq!(v, [7]);
        let w: Vec<u64> = reserve_huge(1 << 20);
        assert!(w.capacity() >= 1 << 20 && w.is_empty());
    }
}
