//! Temporal search regions: a square window around the position predicted for each
//! previous keypoint, or, without a prediction, a wider window around its previous position.

use super::search::SearchRegion;
use crate::features::Keypoint;

/// Window search for temporal matching (previous epoch -> current epoch, same camera).
pub struct GuidedWindow<'p> {
    /// Predicted position per previous keypoint; non-finite means "no prediction".
    pub predicted: Option<&'p [[f32; 2]]>,
    /// Half-size around a prediction, pixels.
    pub window: f32,
    /// Half-size around the previous position when there is no prediction, pixels.
    pub fallback: f32,
    /// Only keypoints with a prediction are searched (the guided pass).
    pub predicted_only: bool,
}

impl GuidedWindow<'_> {
    /// Centre and half-size of the window of previous keypoint `qi`.
    pub fn window_of(&self, qi: usize, q: &Keypoint) -> Option<([f32; 2], f32)> {
        let pred = self
            .predicted
            .and_then(|p| p.get(qi))
            .filter(|p| p[0].is_finite() && p[1].is_finite());
        match pred {
            Some(p) => Some((*p, self.window)),
            None if self.predicted_only => None,
            None if q.x.is_finite() && q.y.is_finite() => Some(([q.x, q.y], self.fallback)),
            None => None,
        }
    }
}

impl SearchRegion for GuidedWindow<'_> {
    type Query = ([f32; 2], f32);

    fn prepare(&self, qi: usize, q: &Keypoint) -> Option<([f32; 4], Self::Query)> {
        let (c, h) = self.window_of(qi, q)?;
        Some(([c[0] - h, c[1] - h, c[0] + h, c[1] + h], (c, h)))
    }

    #[inline]
    fn contains(&self, &(c, h): &Self::Query, _ti: usize, t: &Keypoint) -> bool {
        (t.x - c[0]).abs() <= h && (t.y - c[1]).abs() <= h
    }
}
