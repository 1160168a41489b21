//! A read-only, strided, row-major-or-not view of a 2-D array of `f32` or
//! `f64` samples: how the core reads user data without copying it (NumPy
//! arrays of any strides arrive as one of these).

use crate::error::{Result, SfaError};
use std::marker::PhantomData;

/// A floating-point sample type the core reads (`f32` or `f64`). All
/// arithmetic happens in `f64`.
pub trait Sample: Copy + Send + Sync + 'static {
    /// Converts to `f64` exactly.
    fn to_f64(self) -> f64;
    /// Converts from `f64` (rounding for `f32`).
    fn from_f64(v: f64) -> Self;
}

impl Sample for f64 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
}

impl Sample for f32 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

/// A borrowed `nrows x ncols` matrix with arbitrary element strides.
#[derive(Clone, Copy)]
pub struct View<'a, T> {
    ptr: *const T,
    nrows: usize,
    ncols: usize,
    row_stride: isize,
    col_stride: isize,
    _life: PhantomData<&'a T>,
}

// SAFETY: a View is a shared borrow of `T: Sync` data.
unsafe impl<T: Sync> Send for View<'_, T> {}
unsafe impl<T: Sync> Sync for View<'_, T> {}

impl<'a, T: Sample> View<'a, T> {
    /// A view of a C-contiguous (row-major) slice.
    pub fn from_slice(data: &'a [T], nrows: usize, ncols: usize) -> Result<Self> {
        let need =
            nrows.checked_mul(ncols).ok_or_else(|| SfaError::InvalidArgument("array shape overflows usize".into()))?;
        if data.len() != need {
            return Err(SfaError::ShapeMismatch {
                what: "slice length for the given shape",
                expected: need,
                got: data.len(),
            });
        }
        Ok(View { ptr: data.as_ptr(), nrows, ncols, row_stride: ncols as isize, col_stride: 1, _life: PhantomData })
    }

    /// A view of raw strided memory (strides in elements, may be negative).
    ///
    /// # Safety
    /// Every element `ptr + i*row_stride + j*col_stride` for `i < nrows`,
    /// `j < ncols` must be valid for reads for the lifetime `'a`.
    pub unsafe fn from_raw_parts(
        ptr: *const T,
        nrows: usize,
        ncols: usize,
        row_stride: isize,
        col_stride: isize,
    ) -> Self {
        View { ptr, nrows, ncols, row_stride, col_stride, _life: PhantomData }
    }

    /// Number of rows (samples).
    pub fn nrows(&self) -> usize {
        self.nrows
    }

    /// Number of columns (features).
    pub fn ncols(&self) -> usize {
        self.ncols
    }

    /// Element `(i, j)`; panics (debug) if out of bounds.
    #[inline(always)]
    pub fn get(&self, i: usize, j: usize) -> T {
        debug_assert!(i < self.nrows && j < self.ncols);
        // SAFETY: in bounds by the construction contract.
        unsafe { *self.ptr.offset(i as isize * self.row_stride + j as isize * self.col_stride) }
    }

    /// Rows `start..end` as a view.
    pub fn rows(&self, start: usize, end: usize) -> View<'a, T> {
        assert!(start <= end && end <= self.nrows);
        View {
            // SAFETY: start <= nrows, so the offset stays inside (or one past) the data.
            ptr: if start == self.nrows || self.ncols == 0 {
                self.ptr
            } else {
                unsafe { self.ptr.offset(start as isize * self.row_stride) }
            },
            nrows: end - start,
            ncols: self.ncols,
            row_stride: self.row_stride,
            col_stride: self.col_stride,
            _life: PhantomData,
        }
    }

    /// Row `i` as a slice when the row is contiguous.
    #[inline]
    fn row_slice(&self, i: usize) -> Option<&'a [T]> {
        if self.col_stride == 1 || self.ncols <= 1 {
            // SAFETY: contiguous row of ncols valid elements.
            Some(unsafe { std::slice::from_raw_parts(self.ptr.offset(i as isize * self.row_stride), self.ncols) })
        } else {
            None
        }
    }

    /// Copies row `i` into `out` as `f64`, subtracting `shift` if given.
    #[inline]
    pub fn row_into(&self, i: usize, shift: Option<&[f64]>, out: &mut [f64]) {
        debug_assert_eq!(out.len(), self.ncols);
        match (self.row_slice(i), shift) {
            (Some(r), Some(s)) => {
                for ((o, &v), &c) in out.iter_mut().zip(r).zip(s) {
                    *o = v.to_f64() - c;
                }
            }
            (Some(r), None) => {
                for (o, &v) in out.iter_mut().zip(r) {
                    *o = v.to_f64();
                }
            }
            (None, s) => {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = self.get(i, j).to_f64() - s.map_or(0.0, |s| s[j]);
                }
            }
        }
    }

    /// Returns the first non-finite element, if any (row, column).
    pub fn find_non_finite(&self) -> Option<(usize, usize)> {
        use rayon::prelude::*;
        (0..self.nrows)
            .into_par_iter()
            .find_first(|&i| (0..self.ncols).any(|j| !self.get(i, j).to_f64().is_finite()))
            .map(|i| {
                let j = (0..self.ncols).find(|&j| !self.get(i, j).to_f64().is_finite()).unwrap_or(0);
                (i, j)
            })
    }

    /// Fails with [`SfaError::NonFinite`] if any element is NaN or infinite.
    pub fn check_finite(&self, what: &'static str) -> Result<()> {
        match self.find_non_finite() {
            Some((row, col)) => Err(SfaError::NonFinite { what, row, col }),
            None => Ok(()),
        }
    }
}
