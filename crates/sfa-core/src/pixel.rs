//! Pixel types of the images the network reads: `u8`, `f32` or `f64`.
//!
//! Image batches are borrowed as they come (from NumPy, a file, a test) and
//! converted to `f64` one image at a time, inside the parallel loops that
//! process them: a batch is never copied whole.

use std::borrow::Cow;

/// A pixel value type the network reads (`u8`, `f32` or `f64`). All
/// arithmetic happens in `f64`.
pub trait Pixel: Copy + Send + Sync + 'static {
    /// True when every value of the type is finite (no NaN check needed).
    const ALWAYS_FINITE: bool;
    /// Converts to `f64` exactly.
    fn to_f64(self) -> f64;
    /// The slice as `f64` values: borrowed for `f64`, converted otherwise.
    fn image_f64(image: &[Self]) -> Cow<'_, [f64]> {
        Cow::Owned(image.iter().map(|v| v.to_f64()).collect())
    }
    /// The slice as one of the [`Pixels`] variants.
    fn pixels(data: &[Self]) -> Pixels<'_>;
}

impl Pixel for u8 {
    const ALWAYS_FINITE: bool = true;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn pixels(data: &[Self]) -> Pixels<'_> {
        Pixels::U8(data)
    }
}

impl Pixel for f32 {
    const ALWAYS_FINITE: bool = false;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn pixels(data: &[Self]) -> Pixels<'_> {
        Pixels::F32(data)
    }
}

impl Pixel for f64 {
    const ALWAYS_FINITE: bool = false;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    fn image_f64(image: &[Self]) -> Cow<'_, [f64]> {
        Cow::Borrowed(image)
    }
    fn pixels(data: &[Self]) -> Pixels<'_> {
        Pixels::F64(data)
    }
}

/// Borrowed pixel data of any supported type (row-major
/// `n x height x width x channels`).
#[derive(Clone, Copy, Debug)]
pub enum Pixels<'a> {
    U8(&'a [u8]),
    F32(&'a [f32]),
    F64(&'a [f64]),
}

impl Pixels<'_> {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Pixels::U8(s) => s.len(),
            Pixels::F32(s) => s.len(),
            Pixels::F64(s) => s.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Evaluates `$body` with `$s` bound to the typed slice of a [`Pixels`]
/// value (one monomorphised copy per pixel type).
#[macro_export]
macro_rules! with_pixels {
    ($px:expr, $s:ident => $body:expr) => {
        match $px {
            $crate::Pixels::U8($s) => $body,
            $crate::Pixels::F32($s) => $body,
            $crate::Pixels::F64($s) => $body,
        }
    };
}

/// A batch of `n` images.
#[derive(Clone, Copy, Debug)]
pub struct Batch<'a> {
    pub pixels: Pixels<'a>,
    pub n: usize,
}

impl<'a> Batch<'a> {
    /// A batch of `n` images from a typed slice.
    pub fn new<P: Pixel>(data: &'a [P], n: usize) -> Self {
        Batch { pixels: P::pixels(data), n }
    }
}
