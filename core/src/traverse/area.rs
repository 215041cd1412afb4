//! Tie points carried on by area matching: the previous epoch's stereo observations
//! that the descriptor quads did not continue are looked for in the current images
//! around the place the resected pose projects them to.
//!
//! Why: a quad needs one point detected as a keypoint in four images and matched three
//! times by descriptor. On the rendered streets only about 40 % of an epoch's stereo
//! matches get through (detector repeatability and the ratio test each lose some), so
//! tracks are short and consecutive epochs share few points, which is what lets the
//! attitude (roll above all) wander. Here the prediction is good to a fraction of a
//! pixel (the object point from the window, or intersected from the previous stereo
//! pair; the current pose resected from the descriptor tie points), so a small
//! correlation search is enough and leaves little room for a false match; the stereo
//! refinement then finds the right position, with its back check. Tie points found by
//! descriptors win every conflict, so an image point is observed once.

use super::patches::{PatchInfo, NO_ID};
use super::Traverse;
use crate::camera::{project_to_pixel, Pose, Rig};
use crate::image::ImageView;
use crate::matching::refine::{refine_checked, Correlator, TEMPLATE_LEN};
use crate::matching::StereoPx;
use bytemuck::{Pod, Zeroable};

/// A tie point found by area matching.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct AreaTie {
    /// Template index in the patch store (the previous epoch's observation).
    pub entry: u32,
    /// Observation tag (track id) and window point; [`NO_ID`] until the point exists.
    pub tag: u32,
    pub point: u32,
    /// Current left and right positions, pixels, and the right one's precision.
    pub px: StereoPx,
}

/// Predicted left and right pixels of a template's point, and its depths (metres) at
/// the previous epoch and now.
type Prediction = ([[f32; 2]; 2], (f32, f32));

/// Two observations closer than this (pixels, each axis) are the same image point.
const SAME_POINT_PX: f32 = 1.0;
/// Correlation search radius around the predicted left position, whole pixels: a
/// resected pose predicts to a fraction of a pixel, the motion prediction alone (the
/// resection failed) to a few.
const SEARCH_PX: usize = 2;
const SEARCH_PREDICTED_PX: usize = 3;

fn near(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0] - b[0]).abs() < SAME_POINT_PX && (a[1] - b[1]).abs() < SAME_POINT_PX
}

impl Traverse<'_> {
    /// Whether the templates confirm `prediction` rather than `rotation`, the pose with
    /// the rotation found from the matches, from which [`Self::track_by_area`] just
    /// searched: true when the prediction finds more of them (its tie points are then
    /// the epoch's), else the rotation's are searched again.
    ///
    /// Why: the rotation from the matches takes the scene as far away. In a steady turn
    /// where a near facade has just left the view, the few matches left are near ones
    /// whose parallax it takes for a turn, while the constant-velocity prediction is
    /// right: `drive@320` epoch 424 kept a rotation 0.8 deg off, found 1 area tie point
    /// (44 at the epochs around it) and was lost.
    pub(super) fn area_prefers(
        &mut self,
        left: &ImageView,
        right: &ImageView,
        (rotation, prediction): (&Pose, &Pose),
    ) -> bool {
        let from_rotation = self.n_area;
        self.track_by_area(left, right, (prediction, false));
        if self.n_area > from_rotation {
            return true;
        }
        self.track_by_area(left, right, (rotation, false));
        false
    }

    /// Finds the templates of the previous window epoch that no descriptor tie point
    /// continued in the current images, with the current left pose `initial`
    /// (`resected`: from the resection, else the motion prediction).
    pub(super) fn track_by_area(
        &mut self,
        left: &ImageView,
        right: &ImageView,
        (initial, resected): (&Pose, bool),
    ) {
        self.n_area = 0;
        let (Some(patches), Some(rcfg)) = (&self.patches, self.cfg.matching.refine) else {
            return;
        };
        let Some(last) = self.window.n_epochs().checked_sub(1) else {
            return;
        };
        if patches.epoch().is_none() || self.window.epoch_id(last) != patches.epoch() {
            return;
        }
        let Some(prev_left) = self.window.epoch_pose(last) else {
            return;
        };
        let prev = [prev_left, self.right_of(&prev_left)];
        let cur = [*initial, self.right_of(initial)];
        let rig = self.rig_now();
        // Descriptor and area tie points share the epoch's tie point capacity, which
        // sizes the window (TraverseConfig::fit_capacities).
        let descriptor_ties = self.matcher.tie_points().count();
        let room = self.area.len().min(
            self.cfg
                .matching
                .max_tie_points
                .saturating_sub(descriptor_ties),
        );
        let r = if resected {
            SEARCH_PX
        } else {
            SEARCH_PREDICTED_PX
        };
        let mut tpl = [0f32; TEMPLATE_LEN];
        let mut buf = Correlator::new();
        for i in 0..patches.len() {
            if self.n_area >= room {
                break;
            }
            let (Some(key), Some(mut info)) = (patches.key(i), patches.info(i)) else {
                continue;
            };
            // A point freed since (its slot may hold another track's point) is
            // intersected anew from the template's stereo pair.
            if info.point != NO_ID && self.window.point_tag(info.point) != Some(info.tag) {
                info.point = NO_ID;
                info.tag = NO_ID;
            }
            if self.matcher.tie_points().any(|t| t.prev.left == key) {
                continue;
            }
            let Some(([pl, pr], scale)) = self.predict(&rig, (&prev, &cur), key, &info) else {
                continue;
            };
            // From the anchor epoch, not the previous one, where the template was taken.
            let scale = match (patches.anchor_depth(i), scale) {
                (Some(a), (_, now)) => a / now,
                (None, (before, now)) => before / now,
            };
            if !super::template_at_scale(patches, i, scale, &mut tpl) {
                continue;
            }
            let half = patches.half();
            let Ok(found) = buf.correlate(&tpl, half, left, pl, (r, r), rcfg.min_ncc) else {
                continue;
            };
            let l = buf
                .recentre(&tpl, half, left, found, (1, 1), rcfg.min_ncc)
                .at;
            let Ok(right_peak) = refine_checked(&mut buf, left, right, l, pr, &rcfg) else {
                continue;
            };
            let duplicate = self.matcher.tie_points().any(|t| near(t.cur.left, l))
                || self.area[..self.n_area].iter().any(|a| near(a.px.left, l));
            if duplicate {
                continue;
            }
            self.area[self.n_area] = AreaTie {
                entry: i as u32,
                tag: info.tag,
                point: info.point,
                px: StereoPx {
                    left: l,
                    right: right_peak.at,
                    right_sigma: right_peak.sigma,
                },
            };
            self.n_area += 1;
        }
    }

    /// Current left and right pixel positions predicted for a template's point through
    /// `rig` (the rig as adjusted), and its depths at the previous epoch and now (metres).
    fn predict(
        &self,
        rig: &Rig,
        (prev, cur): (&[Pose; 2], &[Pose; 2]),
        key: [f32; 2],
        info: &PatchInfo,
    ) -> Option<Prediction> {
        let xyz = if info.point != NO_ID {
            self.window.point(info.point)?
        } else {
            super::intersect_pair(&self.cfg, rig, prev, key, info.right)?
        };
        let depth = -cur[0].to_camera(&xyz)[2];
        let before = -prev[0].to_camera(&xyz)[2];
        if !(depth > 0.0 && depth <= self.cfg.max_depth_m && before > 0.0) {
            return None;
        }
        let l = project_to_pixel(&cur[0], &rig.left, &xyz).ok()?;
        let r = project_to_pixel(&cur[1], &rig.right, &xyz).ok()?;
        let px = |p: [f64; 2]| [p[0] as f32, p[1] as f32];
        Some(([px(l), px(r)], (before as f32, depth as f32)))
    }

    /// Adds the area tie points to the window epoch `id` (the previous one is
    /// `prev_id` with poses `prev`): points they already are get the new observations,
    /// the others are intersected from the previous stereo pair first.
    pub(super) fn add_area_ties(&mut self, id: u32, (prev_id, prev): (u32, &[Pose; 2])) -> u32 {
        let rig = self.rig_now();
        let mut new_points = 0;
        for a in 0..self.n_area {
            let t = self.area[a];
            let (tag, point) = if t.point != NO_ID {
                (t.tag, t.point)
            } else {
                let Some(p) = self.patches.as_ref().and_then(|p| {
                    let info = p.info(t.entry as usize)?;
                    Some(StereoPx {
                        left: p.key(t.entry as usize)?,
                        right: info.right,
                        right_sigma: info.right_sigma,
                    })
                }) else {
                    continue;
                };
                let tag = self.matcher.new_track_id();
                let at = (prev_id, prev);
                let geometry = (&self.cfg, &rig);
                let Some(point) = super::new_point(geometry, &mut self.window, at, p, tag) else {
                    continue;
                };
                new_points += 1;
                (tag, point)
            };
            super::add_stereo_observations(&self.cfg, &mut self.window, id, point, t.px, tag);
            self.area[a].tag = tag;
            self.area[a].point = point;
        }
        new_points
    }
}

/// A template's metadata for an area tie point of the current epoch.
impl From<&AreaTie> for PatchInfo {
    fn from(a: &AreaTie) -> Self {
        PatchInfo {
            right: a.px.right,
            right_sigma: a.px.right_sigma,
            tag: a.tag,
            point: a.point,
        }
    }
}
