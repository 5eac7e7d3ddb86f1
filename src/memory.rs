//! Large output buffers backed by huge pages where the system allows it.
//!
//! A polygonizer's output (vertices, normals, triangles) is fresh memory on every call; at 256³
//! it is tens of megabytes, faulted in one 4 KiB page at a time. On Linux with transparent huge
//! pages in `madvise` mode, asking for huge pages before the first write makes it one fault per
//! 2 MiB. Elsewhere this does nothing, and the environment variable `IMPLICITMESH_NO_HUGEPAGES`
//! (set at all) turns it off.
//!
//! [`collect_counted`] fills such a vector in parallel when the number of items each piece of
//! work yields is known beforehand.

use rayon::prelude::*;
use std::mem::MaybeUninit;

/// The bytes a fit or a polygonization may estimate to need before it is refused, when no
/// `memory_limit` is given (8 GiB).
pub const DEFAULT_MEMORY_LIMIT: u64 = 8 << 30;

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

/// Gives the pages of freed memory back to the system, on the calling thread and on every
/// thread of rayon's pool, where the allocator keeps them for reuse (many buffers freed at once
/// stay resident otherwise, and a large buffer allocated next cannot use them): through the
/// hook the global allocator's owner set ([`set_release_hook`]), else glibc's `malloc_trim`
/// on Linux, else nothing.
pub fn release_free_memory() {
    let release = || match RELEASE.get() {
        Some(hook) => hook(),
        None => {
            #[cfg(all(target_os = "linux", target_env = "gnu"))]
            // SAFETY: malloc_trim only returns free pages of glibc's heaps to the system.
            unsafe {
                libc::malloc_trim(0);
            }
        }
    };
    rayon::broadcast(|_| release());
    release();
}

/// What [`release_free_memory`] calls on each thread when the program's global allocator is not
/// the system's (set once; later calls are ignored). Only the Python module sets one.
#[cfg_attr(not(feature = "python"), allow(dead_code))]
pub fn set_release_hook(hook: fn()) {
    let _ = RELEASE.set(hook);
}

static RELEASE: std::sync::OnceLock<fn()> = std::sync::OnceLock::new();

/// Pieces of work per task of [`collect_counted`].
const GROUP: usize = 1024;

/// The items of `items(0)`, `items(1)`, … in that order, in one vector allocated once and
/// filled in parallel; `counts[i]` is the number of items `items(i)` yields.
///
/// Unlike `flat_map_iter(…).collect()`, no per-thread vectors grow and are copied together at
/// the end. A count that disagrees with its items panics (never exposing unwritten memory).
pub fn collect_counted<T, I, F>(counts: &[u32], items: F) -> Vec<T>
where
    T: Send,
    I: IntoIterator<Item = T>,
    F: Fn(usize) -> I + Sync,
{
    let total: usize = counts.iter().map(|&c| c as usize).sum();
    let mut out: Vec<T> = with_capacity_huge(total);
    {
        // The room of each group of GROUP pieces, in order.
        let mut rest: &mut [MaybeUninit<T>] = &mut out.spare_capacity_mut()[..total];
        let mut groups = Vec::with_capacity(counts.len().div_ceil(GROUP));
        for (g, c) in counts.chunks(GROUP).enumerate() {
            let n = c.iter().map(|&c| c as usize).sum();
            let (room, tail) = std::mem::take(&mut rest).split_at_mut(n);
            groups.push((g * GROUP, room));
            rest = tail;
        }
        groups.into_par_iter().for_each(|(first, room)| {
            let mut k = 0;
            for i in first..(first + GROUP).min(counts.len()) {
                for t in items(i) {
                    // (Indexing panics past the group's room.)
                    room[k].write(t);
                    k += 1;
                }
            }
            assert_eq!(k, room.len(), "collect_counted: counts disagree with items");
        });
    }
    // SAFETY: the groups' rooms tile the first `total` slots, and each group wrote every slot of
    // its room (asserted above; a panic there propagates before this line).
    unsafe { out.set_len(total) };
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counted_items_in_order() {
        let counts: Vec<u32> = (0..5000u32).map(|i| i % 7).collect();
        let got = collect_counted(&counts, |i| (0..counts[i]).map(move |k| (i, k)));
        let want: Vec<(usize, u32)> = (0..counts.len())
            .flat_map(|i| (0..counts[i]).map(move |k| (i, k)))
            .collect();
        assert_eq!(got, want);
        assert!(collect_counted(&[], |_| [0u8; 0]).is_empty());
    }

    #[test]
    #[should_panic(expected = "counts disagree")]
    fn too_few_items_panic() {
        collect_counted(&[2, 3], |i| vec![i; 2]);
    }

    #[test]
    #[should_panic]
    fn too_many_items_panic() {
        collect_counted(&[2, 1], |i| vec![i; 2]);
    }

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
