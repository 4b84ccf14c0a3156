//! Cache hints for reads the hardware cannot foresee: a tile's splats in
//! depth order, scattered over an array far larger than the caches.

/// Cache line size assumed by the hints.
const LINE: usize = 64;

/// Asks for every cache line of `item` ahead of its use (a hint; on
/// targets other than x86-64, nothing).
#[inline]
pub(super) fn prefetch<T>(item: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let bytes = std::mem::size_of::<T>();
        if bytes == 0 {
            return;
        }
        let first = (item as *const T).cast::<i8>();
        let mut offset = 0;
        while offset < bytes {
            // SAFETY: a prefetch only hints at an address, here inside
            // `item`; it reads nothing the program sees and cannot fault.
            unsafe { _mm_prefetch(first.add(offset), _MM_HINT_T0) };
            offset += LINE;
        }
        // The last byte's line, which a record not aligned to lines ends on.
        // SAFETY: as above (`bytes - 1` lies inside `item`).
        unsafe { _mm_prefetch(first.add(bytes - 1), _MM_HINT_T0) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}
