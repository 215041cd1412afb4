//! Temporal refinement by image patches: the previous epoch's templates of the tie
//! points are correlated in the current image at their predicted scale, and the patches
//! kept for the next epoch.
use super::*;
use crate::camera::project_to_pixel;

impl Traverse<'_> {
    /// Moves each tie point's current left position onto the spot its left template
    /// shows (magnified by the point's scale change since the template's anchor
    /// epoch), then re-refines the right position from there (see `patches`).
    pub(super) fn refine_temporal(&mut self, left: &ImageView, right: &ImageView) {
        let (Some(patches), Some(rcfg)) = (&self.patches, self.cfg.matching.refine) else {
            return;
        };
        let h = rcfg.half_window as usize;
        let rad = rcfg.search_radius as usize;
        let mut tpl = [0f32; TEMPLATE_LEN];
        let mut buf = Correlator::new();
        let stereo = self.stereo_rig();
        let mut n = 0;
        for tie in self.matcher.tie_points() {
            if n >= self.refined.len() {
                break;
            }
            let Some(entry) = patches.index_of(tie.prev.left) else {
                continue;
            };
            let now = stereo_depth(&self.cfg, &stereo, tie.cur.left, tie.cur.right);
            let scale = anchor_scale(patches.anchor_depth(entry), now);
            if !template_at_scale(patches, entry, scale, &mut tpl) {
                continue;
            }
            let Ok(found) = buf.correlate(&tpl, h, left, tie.cur.left, (rad, rad), rcfg.min_ncc)
            else {
                continue;
            };
            let l = buf.recentre(&tpl, h, left, found, (1, 1), rcfg.min_ncc);
            let Ok(r) = refine_checked(&mut buf, left, right, l.at, tie.cur.right, &rcfg) else {
                continue;
            };
            self.refined[n] = Refined {
                slot: tie.slot,
                entry: entry as u32,
                px: StereoPx {
                    left: l.at,
                    right: r.at,
                    right_sigma: r.sigma,
                },
            };
            n += 1;
        }
        self.n_refined = n;
        for r in self.refined[..n].iter() {
            self.matcher.refine_tie_point(r.slot, r.px);
        }
    }

    /// Renews the templates the next epoch's tie points will start from (`epoch` is
    /// this image's window epoch): the tie points found with a template carry it on
    /// while their scale allows (see `patches`); the other tie points, those found by
    /// area and the other stereo matches' left keypoints get a new template, in that
    /// order of priority.
    pub(super) fn store_patches(
        &mut self,
        fill: usize,
        (left, right): (&ImageView, &ImageView),
        epoch: Option<u32>,
    ) {
        let stereo = self.stereo_rig();
        let Some(patches) = &mut self.patches else {
            return;
        };
        patches.begin(epoch);
        if epoch.is_none() {
            return;
        }
        let limit = self.cfg.max_anchor_scale;
        let (cfg, window) = (&self.cfg, &self.window);
        let carry = |patches: &Patches, entry: usize, at: ([f32; 2], [f32; 2])| {
            let now = stereo_depth(cfg, &stereo, at.0, at.1);
            let s = anchor_scale(patches.anchor_depth(entry), now);
            // A receding point would need a template larger than the anchor's.
            s <= limit && s >= 1.0 - SAME_SCALE
        };
        // The tie points' templates: first every carried one (their slots must not be
        // overwritten), then the new ones.
        for r in self.refined[..self.n_refined].iter() {
            let entry = r.entry as usize;
            let Some(tie) = self.matcher.tie_points().find(|t| t.slot == r.slot) else {
                continue;
            };
            if tie.cur.left != r.px.left || !carry(patches, entry, (r.px.left, r.px.right)) {
                continue;
            }
            let info = tie_info(self.track_points, window, &tie);
            patches.keep(entry, tie.cur.left, info);
        }
        for a in self.area[..self.n_area]
            .iter()
            .filter(|a| a.point != patches::NO_ID)
        {
            if carry(patches, a.entry as usize, (a.px.left, a.px.right)) {
                patches.keep(a.entry as usize, a.px.left, a.into());
            }
        }
        for tie in self.matcher.tie_points() {
            if patches.index_of(tie.cur.left).is_some() {
                continue;
            }
            let info = tie_info(self.track_points, window, &tie);
            let depth = stereo_depth(cfg, &stereo, tie.cur.left, tie.cur.right);
            patches.push(left, tie.cur.left, info, depth);
        }
        for a in self.area[..self.n_area]
            .iter()
            .filter(|a| a.point != patches::NO_ID)
        {
            if patches.index_of(a.px.left).is_none() {
                let depth = stereo_depth(cfg, &stereo, a.px.left, a.px.right);
                patches.push(left, a.px.left, a.into(), depth);
            }
        }
        let quads = self.matcher.quads();
        let kps = self.features[fill][0].keypoints();
        for m in self.matcher.stereo_matches(kps) {
            if !quads.iter().any(|q| q.cur_left == m.left) {
                let depth = stereo_depth(cfg, &stereo, m.left_px, m.right_px);
                let info = PatchInfo::stereo(m.right_px, m.right_sigma);
                patches.push(left, m.left_px, info, depth);
            }
        }
        self.store_line_matches(fill, (left, right));
    }

    /// Fills the rest of the store with the left keypoints the descriptors gave no
    /// right partner, found along their epipolar line by area ([`search_line`]), so
    /// area tracking can carry them on from the next epoch.
    ///
    /// Why: where the detector does not fire at the same spot in both images (sensor
    /// noise, the right camera's other view of a surface), most left keypoints of a
    /// weak image have no right keypoint to pair with; at 320x240 a noisy street kept
    /// about 14 tie points per epoch. Only up to [`LINE_SEARCH_UNTIL`] templates: the
    /// search is the dearest correlation of the epoch (a few hundred positions per
    /// keypoint), and a strong image gains nothing from it.
    fn store_line_matches(&mut self, fill: usize, (left, right): (&ImageView, &ImageView)) {
        let stereo = self.stereo_rig();
        let (Some(patches), Some(rcfg)) = (&mut self.patches, self.cfg.matching.refine) else {
            return;
        };
        let accept = (rcfg.min_ncc, self.cfg.matching.ratio);
        let h = rcfg.half_window as usize;
        let cfg = &self.cfg;
        let kps = self.features[fill][0].keypoints();
        let mut tpl = [0f32; TEMPLATE_LEN];
        let mut buf = Correlator::new();
        let mut live = patches.live();
        for (i, k) in kps.iter().enumerate().take(cfg.matching.max_keypoints) {
            if live >= LINE_SEARCH_UNTIL || !patches.has_room() {
                break;
            }
            let at = [k.x, k.y];
            if self.matcher.has_stereo_match(i) || sample_template(left, at, h, &mut tpl).is_err() {
                continue;
            }
            let Some(line) = epipolar_line(cfg, &stereo, at) else {
                continue;
            };
            let Ok(guess) = search_line(&tpl, h, right, line, accept) else {
                continue;
            };
            let Ok(r) = refine_checked(&mut buf, left, right, at, guess, &rcfg) else {
                continue;
            };
            let depth = stereo_depth(cfg, &stereo, at, r.at);
            let info = PatchInfo::stereo(r.at, r.sigma);
            live += usize::from(patches.push(left, at, info, depth));
        }
    }
}

/// Templates past which no epipolar search is made ([`Traverse::store_line_matches`]).
/// Measured on rendered streets: at 320x240 (a realistic `curves`, a median of 14 to 21
/// tie points per epoch on five of six draws) the searched matches added half as many
/// again or doubled them, and the drift fell to a half or less on three draws and by a
/// third on a fourth; at 640x480 on `traffic` (about 150 tie points) they added half as
/// many again, left the drift as it was and cost a fifth to a half more time per epoch.
const LINE_SEARCH_UNTIL: usize = 96;

/// Nearest depth (metres) an epipolar search reaches on a general rig.
const LINE_NEAR_M: f64 = 1.0;
/// A depth (metres) that stands for infinity at the far end of the search.
const LINE_FAR_M: f64 = 1.0e4;

/// The stretch of the right image where the left pixel `at` may be seen: the row over
/// the disparity range on a rectified pair; on a general rig the line from the point's
/// projection at the stereo search's nearest depth to its vanishing point, through
/// `rig`, the rig as last adjusted.
fn epipolar_line(cfg: &TraverseConfig, stereo: &StereoRig, at: [f32; 2]) -> Option<LineSegment> {
    let (near_m, far_m) = match cfg.matching.stereo {
        StereoGeometry::Rectified {
            min_disparity_px,
            max_disparity_px,
            ..
        } => {
            let range = (min_disparity_px as usize, max_disparity_px as usize);
            return Some(LineSegment::row(at, range));
        }
        StereoGeometry::Rig {
            min_depth_m,
            max_depth_m,
            ..
        } => (min_depth_m.max(LINE_NEAR_M), max_depth_m.min(LINE_FAR_M)),
    };
    let rig = &stereo.rig;
    let [x, y] = rig.left.pixel_to_corrected(at[0] as f64, at[1] as f64);
    let seen_at = |depth: f64| {
        let s = depth / rig.left.focal_mm;
        let p =
            project_to_pixel(&stereo.right_at_origin, &rig.right, &[x * s, y * s, -depth]).ok()?;
        Some([p[0] as f32, p[1] as f32])
    };
    LineSegment::between(seen_at(near_m)?, seen_at(far_m)?)
}

/// What a tie point's template shows: its window point when its track has one.
fn tie_info(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> PatchInfo {
    match known_point(map, window, tie) {
        Some(point) => PatchInfo {
            right: tie.cur.right,
            right_sigma: tie.cur.right_sigma,
            tag: tie.track_id,
            point,
        },
        None => PatchInfo::stereo(tie.cur.right, tie.cur.right_sigma),
    }
}

/// Whether a tie point's track had a window point that the window has since freed.
pub(super) fn has_dead_point(map: &[TrackPoint], window: &Window, tie: &TiePoint) -> bool {
    map.get(tie.slot as usize).is_some_and(|e| {
        e.track_id == tie.track_id
            && e.point != u32::MAX
            && window.point_tag(e.point) != Some(tie.track_id)
    })
}

pub(super) fn same_spot(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0] - b[0]).abs() < SAME_SPOT_PX && (a[1] - b[1]).abs() < SAME_SPOT_PX
}

/// The rig as last adjusted ([`Traverse::rig_now`]) with the right camera's poses the
/// depths and lines of a loop are taken from, worked out once for the loop.
struct StereoRig {
    rig: Rig,
    /// The pair with its left camera at the datum (depths).
    at_datum: [Pose; 2],
    /// The right camera with the left one at the origin (epipolar lines).
    right_at_origin: Pose,
}

impl Traverse<'_> {
    fn stereo_rig(&self) -> StereoRig {
        let rig = self.rig_now();
        let relative = rig.relative();
        let d = self.cfg.datum;
        StereoRig {
            at_datum: [d, camera_pose(&d, &relative, Camera::Right)],
            right_at_origin: camera_pose(&Pose::default(), &relative, Camera::Right),
            rig,
        }
    }
}

/// Depth (metres, along the left camera's axis) of a stereo observation, through
/// the rig as last adjusted; `None` when the rays barely intersect (a far point).
fn stereo_depth(
    cfg: &TraverseConfig,
    stereo: &StereoRig,
    left: [f32; 2],
    right: [f32; 2],
) -> Option<f32> {
    let x = intersect_pair(cfg, &stereo.rig, &stereo.at_datum, left, right)?;
    Some(-stereo.at_datum[0].to_camera(&x)[2] as f32)
}

/// How many times larger a point appears now than at its template's anchor epoch,
/// from the two depths; 1 when either is unknown (a far point).
fn anchor_scale(anchor: Option<f32>, now: Option<f32>) -> f32 {
    match (anchor, now) {
        (Some(a), Some(n)) if n > 0.0 => a / n,
        _ => 1.0,
    }
}

/// Template `entry` of the store as it appears `scale` times larger into `out`;
/// false when there is no such template or it would have to shrink.
pub(super) fn template_at_scale(
    patches: &Patches,
    entry: usize,
    scale: f32,
    out: &mut [f32; TEMPLATE_LEN],
) -> bool {
    let mut anchor = [0f32; TEMPLATE_LEN];
    if !patches.template(entry, &mut anchor) {
        return false;
    }
    if (scale - 1.0).abs() < SAME_SCALE {
        *out = anchor;
        return true;
    }
    magnify_template(&anchor, patches.half(), scale, out)
}
