//! Memory limits: every allocation whose size follows from a caller's
//! dimensions is sized first with checked arithmetic and refused, with an
//! error naming what and how much, when it cannot fit; the large buffers
//! themselves are allocated fallibly (`try_reserve`), so that a failed
//! allocation is an error instead of an abort.
//!
//! The limit is, by default, the machine's physical memory, lowered to
//! what the process's address-space limit (`ulimit -v`) still leaves; it
//! can be set explicitly with [`set_limit`].

use crate::error::{Result, SfaError};
use faer::Mat;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

/// Explicit limit in bytes (0: automatic).
static LIMIT: AtomicUsize = AtomicUsize::new(0);

/// Under the automatic limit, requests below this size are not compared
/// with it (they are still allocated fallibly): reading the process limits
/// costs a system call or two.
const SMALL: usize = 64 << 20;

/// Sets the memory limit in bytes that sized requests are checked against
/// (0 restores the automatic limit: physical memory, or what the address
/// space limit leaves).
pub fn set_limit(bytes: usize) {
    LIMIT.store(bytes, Ordering::Relaxed);
}

/// The explicit limit, if one is set.
pub fn explicit_limit() -> Option<usize> {
    match LIMIT.load(Ordering::Relaxed) {
        0 => None,
        b => Some(b),
    }
}

fn physical_memory() -> usize {
    static PHYS: OnceLock<usize> = OnceLock::new();
    *PHYS.get_or_init(|| read_kib("/proc/meminfo", "MemTotal:").unwrap_or(usize::MAX / 1024).saturating_mul(1024))
}

/// The value in KiB after `key` in a `/proc` file of "Key: value kB" lines.
fn read_kib(path: &str, key: &str) -> Option<usize> {
    let text = std::fs::read_to_string(path).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse().ok()
}

/// What the address-space limit still leaves (None: no limit, or not Linux).
fn address_space_left() -> Option<usize> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    let soft = line["Max address space".len()..].split_whitespace().next()?;
    let soft: usize = soft.parse().ok()?; // "unlimited" -> None
    let used = read_kib("/proc/self/status", "VmSize:").unwrap_or(0).saturating_mul(1024);
    Some(soft.saturating_sub(used))
}

/// The limit a request is checked against now, in bytes.
pub fn limit() -> usize {
    if let Some(b) = explicit_limit() {
        return b;
    }
    let phys = physical_memory();
    address_space_left().map_or(phys, |left| left.min(phys))
}

/// Bytes as a short human figure ("3.4 TB").
pub fn human(bytes: usize) -> String {
    let b = bytes as f64;
    for (unit, size) in [("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)] {
        if b >= size {
            return format!("{:.1} {unit}", b / size);
        }
    }
    format!("{bytes} bytes")
}

/// Bytes of `counts` multiplied together times `elem` bytes each (None on
/// overflow).
pub fn bytes_of(elem: usize, counts: &[usize]) -> Option<usize> {
    counts.iter().try_fold(elem, |acc, &c| acc.checked_mul(c))
}

/// The sum of optional sizes (None if any is None or the sum overflows).
pub fn total(parts: &[Option<usize>]) -> Option<usize> {
    parts.iter().try_fold(0usize, |acc, p| acc.checked_add((*p)?))
}

/// Refuses a request of `bytes` (None: beyond `usize`) for `what` when it
/// exceeds the limit.
pub fn check(what: impl FnOnce() -> String, bytes: Option<usize>) -> Result<()> {
    match bytes {
        Some(b) if b < SMALL && explicit_limit().is_none() => Ok(()),
        Some(b) => {
            let lim = limit();
            if b <= lim {
                Ok(())
            } else {
                Err(SfaError::TooLarge { what: what(), bytes: Some(b), limit: lim })
            }
        }
        None => Err(SfaError::TooLarge { what: what(), bytes: None, limit: limit() }),
    }
}

/// `n` copies of `value`, checked against the limit and allocated
/// fallibly.
pub fn filled<T: Clone>(n: usize, value: T, what: impl FnOnce() -> String) -> Result<Vec<T>> {
    let mut what = Some(what);
    let mut name = || what.take().map_or_else(String::new, |f| f());
    let bytes = bytes_of(std::mem::size_of::<T>(), &[n]);
    check(&mut name, bytes)?;
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| SfaError::TooLarge { what: name(), bytes, limit: limit() })?;
    v.resize(n, value);
    Ok(v)
}

/// An `r x c` zero matrix, checked against the limit and allocated
/// fallibly.
pub fn zeros(r: usize, c: usize, what: impl FnOnce() -> String) -> Result<Mat<f64>> {
    let mut what = Some(what);
    let mut name = || what.take().map_or_else(String::new, |f| f());
    let bytes = bytes_of(8, &[r, c]);
    check(&mut name, bytes)?;
    let mut m = Mat::new();
    m.try_reserve(r, c).map_err(|_| SfaError::TooLarge { what: name(), bytes, limit: limit() })?;
    m.resize_with(r, c, |_, _| 0.0);
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_overflow_to_none() {
        assert_eq!(bytes_of(8, &[3, 4]), Some(96));
        assert_eq!(bytes_of(8, &[usize::MAX, 2]), None);
        assert_eq!(total(&[Some(1), Some(2)]), Some(3));
        assert_eq!(total(&[Some(usize::MAX), Some(1)]), None);
        assert_eq!(total(&[Some(1), None]), None);
    }

    #[test]
    fn requests_beyond_the_limit_are_refused() {
        let e = check(|| "a test buffer".into(), None).unwrap_err();
        assert!(e.to_string().contains("a test buffer"), "{e}");
        let e = check(|| "x".into(), Some(usize::MAX)).unwrap_err();
        assert!(matches!(e, SfaError::TooLarge { .. }));
        assert!(check(|| "x".into(), Some(1024)).is_ok());
        assert!(filled(usize::MAX / 8, 0u64, || "huge".into()).is_err());
        assert!(zeros(1 << 31, 1 << 31, || "huge".into()).is_err());
        assert_eq!(zeros(2, 3, || "small".into()).unwrap().nrows(), 2);
    }

    #[test]
    fn human_sizes() {
        assert_eq!(human(3_400_000_000_000), "3.4 TB");
        assert_eq!(human(512), "512 bytes");
    }
}
