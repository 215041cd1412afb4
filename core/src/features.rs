//! Keypoints and descriptors: the data the extractor (`sift`) hands to `matching`.

use bytemuck::{Pod, Zeroable};

/// One scale-space keypoint.
///
/// Position in the pixel convention of [`crate::image`]: `(0, 0)` is the centre
/// of the top-left pixel, x right (column), y down (row).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Keypoint {
    /// Column, pixels.
    pub x: f32,
    /// Row, pixels.
    pub y: f32,
    /// Scale: Gaussian sigma in pixels of the input image.
    pub sigma: f32,
    /// Orientation in radians, measured from +x towards +y (image rows down), in `[0, 2 pi)`.
    pub orientation: f32,
    /// Absolute DoG response at the refined extremum (grey levels / 255); ranks keypoints.
    pub response: f32,
    /// Octave (0 = input resolution).
    pub octave: u16,
    /// Region of the spreading grid the keypoint belongs to.
    pub cell: u16,
}

/// A SIFT descriptor: 4x4 spatial cells x 8 orientation bins, quantised to u8.
pub type Descriptor = [u8; 128];
