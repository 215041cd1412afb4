//! Integer image buffers: borrowed views over caller storage.
//!
//! Pixel convention (docs/conventions.md, "Pixel convention"): pixel centres at
//! integer coordinates, `(0, 0)` is the centre of the top-left pixel, `c` is the
//! column and `r` the row.

/// Why an image buffer was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageError {
    /// Width or height is zero.
    Empty,
    /// The stride is smaller than the width.
    BadStride,
    /// The buffer holds fewer bytes than `stride * (height - 1) + width`.
    BufferTooSmall { needed: usize, got: usize },
    /// The image is larger than the configured capacity.
    TooLarge {
        width: usize,
        height: usize,
        max_width: usize,
        max_height: usize,
    },
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ImageError::Empty => write!(f, "image has zero width or height"),
            ImageError::BadStride => write!(f, "image stride is smaller than its width"),
            ImageError::BufferTooSmall { needed, got } => {
                write!(f, "image buffer holds {got} bytes, {needed} needed")
            }
            ImageError::TooLarge {
                width,
                height,
                max_width,
                max_height,
            } => write!(
                f,
                "image {width}x{height} exceeds the configured capacity {max_width}x{max_height}"
            ),
        }
    }
}

/// A read-only 8-bit gray image over a borrowed byte slice (row-major, with stride).
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageView<'a> {
    /// A tightly packed image (`stride == width`).
    pub fn new(data: &'a [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::with_stride(data, width, height, width)
    }

    /// An image whose rows start every `stride` bytes.
    pub fn with_stride(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        if width == 0 || height == 0 {
            return Err(ImageError::Empty);
        }
        if stride < width {
            return Err(ImageError::BadStride);
        }
        let needed = stride
            .checked_mul(height - 1)
            .and_then(|n| n.checked_add(width))
            .ok_or(ImageError::BufferTooSmall {
                needed: usize::MAX,
                got: data.len(),
            })?;
        if data.len() < needed {
            return Err(ImageError::BufferTooSmall {
                needed,
                got: data.len(),
            });
        }
        Ok(ImageView {
            data,
            width,
            height,
            stride,
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Row `r` as a slice of `width` pixels. Panics only if `r >= height` (caller bug).
    #[inline]
    pub fn row(&self, r: usize) -> &'a [u8] {
        let start = r * self.stride;
        &self.data[start..start + self.width]
    }

    /// Pixel at column `c`, row `r`, or `None` outside the image.
    #[inline]
    pub fn get(&self, c: usize, r: usize) -> Option<u8> {
        if c < self.width && r < self.height {
            Some(self.data[r * self.stride + c])
        } else {
            None
        }
    }

    /// Checks the view against a configured capacity.
    pub fn check_capacity(&self, max_width: usize, max_height: usize) -> Result<(), ImageError> {
        if self.width > max_width || self.height > max_height {
            return Err(ImageError::TooLarge {
                width: self.width,
                height: self.height,
                max_width,
                max_height,
            });
        }
        Ok(())
    }
}

/// Scales 16-bit samples with `bits` significant bits to 8 bits (keeps the top 8 bits).
///
/// Writes `min(src.len(), dst.len())` samples and returns that count; `bits` is
/// clamped to `8..=16`.
pub fn scale_u16_to_u8(src: &[u16], dst: &mut [u8], bits: u32) -> usize {
    let shift = bits.clamp(8, 16) - 8;
    let n = src.len().min(dst.len());
    for (d, &s) in dst[..n].iter_mut().zip(&src[..n]) {
        *d = (s >> shift).min(255) as u8;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_shapes() {
        let buf = [0u8; 10];
        assert_eq!(ImageView::new(&buf, 0, 3).unwrap_err(), ImageError::Empty);
        assert_eq!(
            ImageView::with_stride(&buf, 4, 2, 3).unwrap_err(),
            ImageError::BadStride
        );
        assert!(matches!(
            ImageView::new(&buf, 4, 3).unwrap_err(),
            ImageError::BufferTooSmall {
                needed: 12,
                got: 10
            }
        ));
        // stride * (h-1) + w = 4*2 + 2 = 10 fits exactly.
        let v = ImageView::with_stride(&buf, 2, 3, 4).unwrap();
        assert_eq!(v.row(2).len(), 2);
        assert_eq!(v.get(2, 0), None);
    }

    #[test]
    fn scales_sixteen_bit() {
        let src = [0u16, 4095, 2048, 65535];
        let mut dst = [0u8; 4];
        assert_eq!(scale_u16_to_u8(&src, &mut dst, 12), 4);
        assert_eq!(dst, [0, 255, 128, 255]);
    }
}
