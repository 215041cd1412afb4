//! The per-epoch matcher: stereo at epoch k, temporal k-1 -> k on both sides (guided,
//! with fallback), quad loop closure, spreading, tracks. All buffers come from the arena
//! in [`Matcher::new`], exactly as [`MatchConfig::budget`] predicts.
//!
//! Cost per epoch, with `n = max_keypoints` and `m = max_candidates`: three matching
//! passes of at most `n * m` early-exit distances each (stereo, temporal left, temporal
//! right; a failed guided temporal pass adds one fallback pass per side), grid builds
//! O(n + buckets), two O(n log n) sorts for the spreading and O(n + max_tracks) for tracks.

use super::config::{carve, MatchConfig, MatchError, StereoGeometry, NONE};
use super::grid::Grid;
use super::motion::{check_motion, QuadObs};
use super::predict::predict_positions;
use super::quad::{close_loops, LoopDistances, Quad, QuadStats};
use super::refine::{refine_checked, Correlator, RefineError};
use super::search::{match_pass, Best, Features, PairStats, PassParams};
use super::spread::spread;
use super::stereo::{BinnedMedian, EpipolarOffset, RectifiedBand, RigBand};
use super::temporal::GuidedWindow;
use super::tracks::{Observation, StereoPx, TrackStats, Tracks};
use crate::budget::Arena;
use crate::camera::{Pose, Rig};
use crate::image::ImageView;

/// The two images of one epoch.
#[derive(Debug, Clone, Copy)]
pub struct StereoFeatures<'k> {
    pub left: Features<'k>,
    pub right: Features<'k>,
}

/// What the stereo step did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StereoStats {
    pub pass: PairStats,
    /// Keypoints beyond `max_keypoints` or with non-finite coordinates (both images).
    pub ignored_keypoints: u32,
    /// Matches whose position the NCC refinement moved.
    pub refined: u32,
    /// Matches the refinement rejected (flat, low score, peak on the edge).
    pub refine_rejected: u32,
    /// Matches left unrefined because the template touched the border.
    pub refine_border: u32,
}

/// How a temporal pass found its matches.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum TemporalMode {
    /// Not run (first epoch).
    #[default]
    None,
    /// Windows around the predicted positions were enough.
    Guided,
    /// No prediction, or the guided pass found too few: wide windows around the previous positions.
    Fallback,
}

/// The outcome of one epoch, in the order of the checks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum MatchOutcome {
    /// Tie points found.
    #[default]
    Ok,
    /// First epoch (or restart): stereo matches only, no tie points yet.
    FirstEpoch,
    /// An image of the epoch has no usable keypoints.
    NoKeypoints,
    /// No stereo match at this epoch (for example all keypoints identical).
    NoStereoMatches,
    /// The current frames repeat the previous ones (every temporal match has zero
    /// motion): the epoch is ignored and the matcher state is left as it was.
    RepeatedFrame,
    /// Fewer than `min_temporal_matches` tie points: the images do not continue the
    /// previous epoch (a frame from another place, a large jump). Tracks end.
    Lost,
}

/// Report of one epoch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpochReport {
    pub status: MatchOutcome,
    pub stereo: StereoStats,
    pub left_temporal: PairStats,
    pub right_temporal: PairStats,
    pub left_mode: TemporalMode,
    pub right_mode: TemporalMode,
    /// Stereo matches of the previous epoch with a motion prediction.
    pub predictions: u32,
    pub quads: QuadStats,
    /// Closed quads left out by the spreading (`max_tie_points`).
    pub spread_dropped: u32,
    pub tracks: TrackStats,
    /// Tie points of this epoch (quads with a track).
    pub tie_points: u32,
}

/// One stereo match of the current epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoMatch {
    pub left: u32,
    pub right: u32,
    /// Left keypoint position (pixels).
    pub left_px: [f32; 2],
    /// Right position (pixels): the keypoint's, or the refined one.
    pub right_px: [f32; 2],
    /// The refined right position's precision (pixels; x, y), zero when unrefined.
    pub right_sigma: [f32; 2],
    /// Squared descriptor distance.
    pub distance: u32,
}

/// A tie point of the current epoch: a track seen in the four images of k-1 and k.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiePoint {
    /// Persistent track identity.
    pub track_id: u32,
    /// Track slot (index into [`Matcher::tracks`]).
    pub slot: u32,
    /// Epochs the track has been seen, this one included.
    pub length: u32,
    pub prev: Observation,
    pub cur: Observation,
}

/// Per-keypoint stereo result kept from one epoch to the next (double buffered).
struct StereoSide<'a> {
    /// Right index per left keypoint, [`NONE`] when unmatched.
    right_of: &'a mut [u32],
    /// Right pixel position per left keypoint (refined when enabled).
    right_px: &'a mut [[f32; 2]],
    /// Its precision from the refinement (pixels; x, y), zero when unrefined.
    right_sigma: &'a mut [[f32; 2]],
    /// Descriptor distance per left keypoint.
    dist: &'a mut [u32],
    /// Track slot per left keypoint.
    track: &'a mut [u32],
    n_left: usize,
    n_right: usize,
    /// Fingerprint of the keypoints these results belong to.
    fingerprint: u64,
}

impl<'a> StereoSide<'a> {
    fn new(arena: &mut Arena<'a>, n: usize) -> Result<Self, MatchError> {
        let s = StereoSide {
            right_of: carve(arena, n)?,
            right_px: carve(arena, n)?,
            right_sigma: carve(arena, n)?,
            dist: carve(arena, n)?,
            track: carve(arena, n)?,
            n_left: 0,
            n_right: 0,
            fingerprint: 0,
        };
        s.right_of.fill(NONE);
        s.track.fill(NONE);
        Ok(s)
    }
}

/// Matching state over the traverse.
pub struct Matcher<'a> {
    cfg: MatchConfig,
    grid: Grid<'a>,
    qbest: &'a mut [Best],
    tbest: &'a mut [Best],
    corrected: &'a mut [[f32; 2]],
    left_temporal: &'a mut [u32],
    right_temporal: &'a mut [u32],
    left_temporal_dist: &'a mut [u32],
    right_temporal_dist: &'a mut [u32],
    pred_left: &'a mut [[f32; 2]],
    pred_right: &'a mut [[f32; 2]],
    quads: &'a mut [Quad],
    ranks: &'a mut [u32],
    quad_obs: &'a mut [QuadObs],
    quad_pts: &'a mut [[f64; 3]],
    quad_inlier: &'a mut [u8],
    prev: StereoSide<'a>,
    cur: StereoSide<'a>,
    tracks: Tracks<'a>,
    /// Epoch counter (incremented by each accepted epoch).
    epoch: u32,
    has_prev: bool,
    /// Temporal matches of the last epoch, per side (left, right): a guided pass far
    /// below them has been misled by its prediction (see [`Matcher::temporal`]).
    last_temporal: [u32; 2],
    /// The last stereo result is in `cur` (a standalone or rejected epoch), else in `prev`.
    stereo_in_cur: bool,
    n_tie: usize,
}

impl<'a> Matcher<'a> {
    /// Carves every buffer from `arena` (see [`MatchConfig::budget`]).
    pub fn new(cfg: MatchConfig, arena: &mut Arena<'a>) -> Result<Self, MatchError> {
        cfg.validate()?;
        let n = cfg.max_keypoints;
        let (gc, gr) = cfg.grid_shape();
        Ok(Matcher {
            grid: Grid::new(arena, gc, gr, cfg.cell_px, n)?,
            qbest: carve(arena, n)?,
            tbest: carve(arena, n)?,
            corrected: carve(arena, n)?,
            left_temporal: carve(arena, n)?,
            right_temporal: carve(arena, n)?,
            left_temporal_dist: carve(arena, n)?,
            right_temporal_dist: carve(arena, n)?,
            pred_left: carve(arena, n)?,
            pred_right: carve(arena, n)?,
            quad_obs: carve(arena, n)?,
            quad_pts: carve(arena, 2 * n)?,
            quad_inlier: carve(arena, n)?,
            quads: carve(arena, n)?,
            ranks: carve(arena, n)?,
            prev: StereoSide::new(arena, n)?,
            cur: StereoSide::new(arena, n)?,
            tracks: Tracks::new(arena, cfg.max_tracks, cfg.track_history)?,
            cfg,
            epoch: 0,
            has_prev: false,
            last_temporal: [0; 2],
            stereo_in_cur: false,
            n_tie: 0,
        })
    }

    pub fn config(&self) -> &MatchConfig {
        &self.cfg
    }

    pub fn tracks(&self) -> &Tracks<'a> {
        &self.tracks
    }

    /// Index of the last accepted epoch.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    fn params(&self) -> PassParams {
        PassParams {
            ratio: self.cfg.ratio,
            max_distance: self.cfg.max_distance,
            max_candidates: self.cfg.max_candidates,
        }
    }

    /// The stereo search's side of a pair: the left keypoints searched (`nl`), the
    /// right ones (within the capacity) indexed in the grid, and how many keypoints of
    /// the pair are left out (beyond the capacity, or not placeable in the grid).
    fn index_pair<'p>(&mut self, pair: &StereoFeatures<'p>) -> (usize, Features<'p>, u32) {
        let n = self.cfg.max_keypoints;
        let (nl, nr) = (pair.left.usable(n), pair.right.usable(n));
        let right = Features::new(&pair.right.keypoints[..nr], &pair.right.descriptors[..nr]);
        let beyond = pair.left.keypoints.len() - nl + pair.right.keypoints.len() - nr;
        let unplaced = self.grid.build(right.keypoints);
        (nl, right, (beyond + unplaced) as u32)
    }

    /// Stereo matching of one pair into the `cur` buffers.
    fn stereo_into_cur(
        &mut self,
        pair: StereoFeatures<'_>,
        images: Option<(ImageView<'_>, ImageView<'_>)>,
    ) -> StereoStats {
        let n = self.cfg.max_keypoints;
        let (nl, right, ignored_keypoints) = self.index_pair(&pair);
        let nr = right.keypoints.len();
        let mut stats = StereoStats {
            ignored_keypoints,
            ..Default::default()
        };
        let params = self.params();
        self.stereo_in_cur = true;
        let cur = &mut self.cur;
        cur.n_left = nl;
        cur.n_right = nr;
        cur.fingerprint = fingerprint(&pair, n);
        cur.track[..].fill(NONE);
        stats.pass = match self.cfg.stereo {
            StereoGeometry::Rectified {
                row_tolerance_px,
                min_disparity_px,
                max_disparity_px,
            } => {
                let band = RectifiedBand {
                    row_tol: row_tolerance_px,
                    dmin: min_disparity_px,
                    dmax: max_disparity_px,
                };
                match_pass(
                    &band,
                    pair.left,
                    right,
                    nl,
                    &self.grid,
                    params,
                    self.qbest,
                    self.tbest,
                    cur.right_of,
                )
            }
            StereoGeometry::Rig {
                rig,
                tolerance_px,
                min_depth_m,
                max_depth_m,
            } => {
                let depth = (min_depth_m, max_depth_m);
                let band =
                    RigBand::over(&rig, tolerance_px, depth, right.keypoints, self.corrected);
                match_pass(
                    &band,
                    pair.left,
                    right,
                    nl,
                    &self.grid,
                    params,
                    self.qbest,
                    self.tbest,
                    cur.right_of,
                )
            }
        };
        cur.right_of[nl..].fill(NONE);
        let mut buf = Correlator::new();
        for i in 0..nl {
            cur.dist[i] = self.qbest[i].d1;
            let j = cur.right_of[i];
            if j == NONE {
                continue;
            }
            let (kl, kr) = (&pair.left.keypoints[i], &right.keypoints[j as usize]);
            cur.right_px[i] = [kr.x, kr.y];
            cur.right_sigma[i] = [0.0; 2];
            let (Some(rc), Some((li, ri))) = (self.cfg.refine, images) else {
                continue;
            };
            match refine_checked(&mut buf, &li, &ri, [kl.x, kl.y], [kr.x, kr.y], &rc) {
                Ok(p) => {
                    cur.right_px[i] = p.at;
                    cur.right_sigma[i] = p.sigma;
                    stats.refined += 1;
                }
                Err(RefineError::Border) => stats.refine_border += 1,
                Err(_) => {
                    cur.right_of[i] = NONE;
                    stats.refine_rejected += 1;
                    stats.pass.matches = stats.pass.matches.saturating_sub(1);
                }
            }
        }
        stats
    }

    /// Where the right keypoints of a general rig's pair lie across their epipolar
    /// lines: descriptor matches in a band `widen_px` wider than the configured one,
    /// their median distance from the lines (`None` with a rectified search or fewer
    /// than `min_matches`). The configured band keeps only the matches whose noise
    /// leans towards the lines when the calibration puts the lines a pixel or two off,
    /// so what it keeps cannot show the offset; the wider band can. Uses the
    /// current-epoch buffers as scratch (the next [`Matcher::process_epoch`]
    /// overwrites them).
    pub fn epipolar_offset(
        &mut self,
        pair: StereoFeatures<'_>,
        widen_px: f32,
        min_matches: usize,
    ) -> Option<EpipolarOffset> {
        let StereoGeometry::Rig {
            rig,
            tolerance_px,
            min_depth_m,
            max_depth_m,
        } = self.cfg.stereo
        else {
            return None;
        };
        let (nl, right, _) = self.index_pair(&pair);
        let depth = (min_depth_m, max_depth_m);
        let tolerance = tolerance_px + widen_px;
        let params = self.params();
        let band = RigBand::over(&rig, tolerance, depth, right.keypoints, self.corrected);
        let out = &mut *self.cur.right_of;
        match_pass(
            &band, pair.left, right, nl, &self.grid, params, self.qbest, self.tbest, out,
        );
        // The current-epoch buffers hold no stereo results now.
        self.stereo_in_cur = false;
        let px = rig.right.pixel_size_mm[1];
        let mut median = BinnedMedian::new(tolerance as f64);
        let mut normal = [0.0; 2];
        for (i, &j) in out[..nl].iter().enumerate() {
            let across = (j != NONE)
                .then(|| band.across(&pair.left.keypoints[i], j as usize))
                .flatten();
            if let Some((d, nv)) = across {
                median.add(d / px);
                normal = [normal[0] + nv[0], normal[1] + nv[1]];
            }
        }
        let norm = libm::sqrt(normal[0] * normal[0] + normal[1] * normal[1]);
        if median.count() < min_matches.max(1) || norm.is_nan() || norm <= 0.0 {
            return None;
        }
        Some(EpipolarOffset {
            median_px: median.median()?,
            normal: [normal[0] / norm, normal[1] / norm],
            matches: median.count() as u32,
        })
    }

    /// Stereo matches of one pair only (no temporal state is touched except the
    /// current-epoch buffers, which the next [`Matcher::process_epoch`] overwrites).
    pub fn match_stereo(
        &mut self,
        pair: StereoFeatures<'_>,
        images: Option<(ImageView<'_>, ImageView<'_>)>,
    ) -> StereoStats {
        self.stereo_into_cur(pair, images)
    }

    /// The stereo matches of the last call (current epoch).
    pub fn stereo_matches<'s>(
        &'s self,
        left: &'s [crate::features::Keypoint],
    ) -> impl Iterator<Item = StereoMatch> + 's {
        let cur = self.last_stereo();
        (0..cur.n_left.min(left.len())).filter_map(move |i| {
            let j = cur.right_of[i];
            (j != NONE).then(|| StereoMatch {
                left: i as u32,
                right: j,
                left_px: [left[i].x, left[i].y],
                right_px: cur.right_px[i],
                right_sigma: cur.right_sigma[i],
                distance: cur.dist[i],
            })
        })
    }

    /// Whether left keypoint `i` of the last stereo pass (current epoch) has a right match.
    pub fn has_stereo_match(&self, i: usize) -> bool {
        let side = self.last_stereo();
        i < side.n_left && side.right_of[i] != NONE
    }

    /// The buffers of the last stereo pass: `cur` until `accept_epoch` swaps them into
    /// `prev`.
    fn last_stereo(&self) -> &StereoSide<'a> {
        if self.stereo_in_cur {
            &self.cur
        } else {
            &self.prev
        }
    }

    /// One temporal pass (one camera) with the fallback policy.
    fn temporal(
        &mut self,
        prev: Features<'_>,
        cur: Features<'_>,
        right_side: bool,
        guided: bool,
    ) -> (PairStats, TemporalMode) {
        let n = self.cfg.max_keypoints;
        let (np, nc) = (prev.usable(n), cur.usable(n));
        let cur = Features::new(&cur.keypoints[..nc], &cur.descriptors[..nc]);
        self.grid.build(cur.keypoints);
        let params = self.params();
        let (out, dist, pred) = if right_side {
            (
                &mut *self.right_temporal,
                &mut *self.right_temporal_dist,
                &*self.pred_right,
            )
        } else {
            (
                &mut *self.left_temporal,
                &mut *self.left_temporal_dist,
                &*self.pred_left,
            )
        };
        out.fill(NONE);
        let mut run = |region: &GuidedWindow<'_>, out: &mut [u32], dist: &mut [u32]| {
            let s = match_pass(
                region, prev, cur, np, &self.grid, params, self.qbest, self.tbest, out,
            );
            for (d, b) in dist.iter_mut().zip(self.qbest.iter()).take(np) {
                *d = b.d1;
            }
            s
        };
        let side = right_side as usize;
        let guided_region = GuidedWindow {
            predicted: Some(&pred[..np]),
            window: self.cfg.temporal_window_px,
            fallback: self.cfg.fallback_window_px,
            predicted_only: true,
        };
        // A guided pass is trusted unless it finds fewer than the absolute minimum, or
        // under half of the last epoch's matches: a wrong prediction (the onset of a
        // turn, a jolt) finds a few, and partly wrong, matches inside its windows.
        let enough = (self.cfg.min_temporal_matches as u32).max(self.last_temporal[side] / 2);
        let mut guided_stats = None;
        if guided {
            let s = run(&guided_region, out, dist);
            if s.matches >= enough {
                self.last_temporal[side] = s.matches;
                return (s, TemporalMode::Guided);
            }
            guided_stats = Some(s);
        }
        let region = GuidedWindow {
            predicted: None,
            window: self.cfg.temporal_window_px,
            fallback: self.cfg.fallback_window_px,
            predicted_only: false,
        };
        out.fill(NONE);
        let s = run(&region, out, dist);
        if let Some(g) = guided_stats.filter(|g| g.matches > s.matches) {
            // The prediction was right after all, the scene poorer: keep the guided pass.
            out.fill(NONE);
            let s = run(&guided_region, out, dist);
            debug_assert_eq!(s.matches, g.matches);
            self.last_temporal[side] = s.matches;
            return (s, TemporalMode::Guided);
        }
        self.last_temporal[side] = s.matches;
        (s, TemporalMode::Fallback)
    }

    /// Replaces the rig of a general rig's stereo search ([`StereoGeometry::Rig`]) by
    /// `rig`, a calibration corrected since; a rectified search keeps its rows.
    pub fn set_rig(&mut self, rig: &Rig) {
        if let StereoGeometry::Rig { rig: r, .. } = &mut self.cfg.stereo {
            *r = *rig;
        }
    }

    /// Matches one epoch. `prev` must be the features passed as `cur` in the last
    /// accepted call (or `None` to start over: first epoch, or after a break).
    /// `motion` (the rig and the current left camera's pose in the previous left
    /// camera's frame, see `super::predict`) guides the temporal search.
    pub fn process_epoch(
        &mut self,
        cur: StereoFeatures<'_>,
        prev: Option<StereoFeatures<'_>>,
        images: Option<(ImageView<'_>, ImageView<'_>)>,
        motion: Option<(&Rig, &Pose)>,
    ) -> Result<EpochReport, MatchError> {
        let rig = motion.map(|(r, _)| r);
        self.process_epoch_with(cur, prev, images, rig, motion.map(|(_, p)| p))
    }

    /// [`Matcher::process_epoch`] with the rig given on its own: with a rig and no
    /// motion the temporal search falls back to wide windows, but the rigid-motion
    /// check of the quads ([`MatchConfig::motion_check`]) still runs.
    pub fn process_epoch_with(
        &mut self,
        cur: StereoFeatures<'_>,
        prev: Option<StereoFeatures<'_>>,
        images: Option<(ImageView<'_>, ImageView<'_>)>,
        rig: Option<&Rig>,
        motion: Option<&Pose>,
    ) -> Result<EpochReport, MatchError> {
        let motion = rig.zip(motion);
        for f in [
            Some(cur.left),
            Some(cur.right),
            prev.map(|p| p.left),
            prev.map(|p| p.right),
        ]
        .into_iter()
        .flatten()
        {
            if f.keypoints.len() != f.descriptors.len() {
                return Err(MatchError::LengthMismatch);
            }
        }
        let n = self.cfg.max_keypoints;
        if let Some(p) = prev {
            if !self.has_prev || fingerprint(&p, n) != self.prev.fingerprint {
                return Err(MatchError::PreviousMismatch);
            }
        }
        let mut report = EpochReport::default();
        self.n_tie = 0;
        report.stereo = self.stereo_into_cur(cur, images);
        let Some(prev) = prev else {
            self.tracks.clear();
            report.status = self.stereo_status(&cur).unwrap_or(MatchOutcome::FirstEpoch);
            self.accept_epoch();
            return Ok(report);
        };
        // Temporal matching, guided by the motion prediction when there is one.
        let mut guided = false;
        if let Some((rig, pose)) = motion {
            let np = prev.left.usable(n);
            report.predictions = predict_positions(
                rig,
                pose,
                &prev.left.keypoints[..np],
                &prev.right.keypoints[..prev.right.usable(n)],
                &self.prev.right_of[..np],
                self.pred_left,
                self.pred_right,
            ) as u32;
            guided = report.predictions > 0;
        }
        (report.left_temporal, report.left_mode) =
            self.temporal(prev.left, cur.left, false, guided);
        (report.right_temporal, report.right_mode) =
            self.temporal(prev.right, cur.right, true, guided);
        if self.is_repeated(prev, cur) {
            // Leave every buffer of the previous epoch as it was.
            report.status = MatchOutcome::RepeatedFrame;
            return Ok(report);
        }
        self.close_quads(prev, cur, rig, &mut report);
        report.status = match self.stereo_status(&cur) {
            Some(s) => s,
            None if (report.tie_points as usize) < self.cfg.min_temporal_matches => {
                MatchOutcome::Lost
            }
            None => MatchOutcome::Ok,
        };
        self.accept_epoch();
        Ok(report)
    }

    fn stereo_status(&self, cur: &StereoFeatures<'_>) -> Option<MatchOutcome> {
        if cur.left.keypoints.is_empty() || cur.right.keypoints.is_empty() {
            Some(MatchOutcome::NoKeypoints)
        } else if self.cur.right_of[..self.cur.n_left]
            .iter()
            .all(|&j| j == NONE)
        {
            Some(MatchOutcome::NoStereoMatches)
        } else {
            None
        }
    }

    /// A repeated frame: temporal matches exist and (nearly) all have exactly zero motion.
    fn is_repeated(&self, prev: StereoFeatures<'_>, cur: StereoFeatures<'_>) -> bool {
        let n = self.cfg.max_keypoints;
        let (mut total, mut still) = (0u32, 0u32);
        for (i, &a) in self.left_temporal[..prev.left.usable(n)].iter().enumerate() {
            if a == NONE {
                continue;
            }
            let (p, c) = (&prev.left.keypoints[i], &cur.left.keypoints[a as usize]);
            total += 1;
            if (p.x - c.x).abs() < 1e-3 && (p.y - c.y).abs() < 1e-3 {
                still += 1;
            }
        }
        total > 0 && still * 10 >= total * 9
    }

    fn close_quads(
        &mut self,
        prev: StereoFeatures<'_>,
        cur: StereoFeatures<'_>,
        rig: Option<&Rig>,
        report: &mut EpochReport,
    ) {
        let n = self.cfg.max_keypoints;
        let np = prev.left.usable(n);
        let dist = LoopDistances {
            prev_stereo: self.prev.dist,
            left_temporal: self.left_temporal_dist,
            right_temporal: self.right_temporal_dist,
            cur_stereo: self.cur.dist,
        };
        let nq = close_loops(
            &self.prev.right_of[..np],
            self.left_temporal,
            self.right_temporal,
            self.cur.right_of,
            &dist,
            self.quads,
            &mut report.quads,
        );
        let nq = match (rig, self.cfg.motion_check) {
            (Some(rig), Some(mc)) => self.motion_filter(prev, cur, rig, &mc, nq, &mut report.quads),
            _ => nq,
        };
        for q in self.quads[..nq].iter_mut() {
            q.track = self.prev.track[q.prev_left as usize];
            q.age = self
                .tracks
                .slots()
                .get(q.track as usize)
                .map_or(0, |t| t.length);
        }
        let size = (self.cfg.image_width, self.cfg.image_height);
        let grid = (self.cfg.spread_cols, self.cfg.spread_rows);
        let keep = spread(
            &mut self.quads[..nq],
            cur.left.keypoints,
            size,
            grid,
            self.cfg.max_tie_points,
            self.ranks,
        );
        report.spread_dropped = (nq - keep) as u32;
        let epoch = self.epoch.wrapping_add(1);
        let (pl, cl) = (prev.left.keypoints, cur.left.keypoints);
        let (pside, cside) = (&self.prev, &self.cur);
        report.tracks = self.tracks.update(epoch, &mut self.quads[..keep], |q| {
            let (i, a) = (q.prev_left as usize, q.cur_left as usize);
            (
                Observation {
                    epoch: epoch.wrapping_sub(1),
                    left: [pl[i].x, pl[i].y],
                    right: pside.right_px[i],
                    right_sigma: pside.right_sigma[i],
                },
                Observation {
                    epoch,
                    left: [cl[a].x, cl[a].y],
                    right: cside.right_px[a],
                    right_sigma: cside.right_sigma[a],
                },
            )
        });
        // Keep only quads with a track, in order.
        let mut k = 0;
        for i in 0..keep {
            let q = self.quads[i];
            if q.track != NONE {
                self.cur.track[q.cur_left as usize] = q.track;
                self.quads[k] = q;
                k += 1;
            }
        }
        self.n_tie = k;
        report.tie_points = k as u32;
    }

    /// Removes the quads inconsistent with one rigid motion; returns the count kept.
    fn motion_filter(
        &mut self,
        prev: StereoFeatures<'_>,
        cur: StereoFeatures<'_>,
        rig: &Rig,
        mc: &super::motion::MotionCheckConfig,
        nq: usize,
        stats: &mut QuadStats,
    ) -> usize {
        let (pl, cl) = (prev.left.keypoints, cur.left.keypoints);
        for (o, q) in self.quad_obs.iter_mut().zip(self.quads[..nq].iter()) {
            let (i, a) = (q.prev_left as usize, q.cur_left as usize);
            *o = [
                [pl[i].x, pl[i].y],
                self.prev.right_px[i],
                [cl[a].x, cl[a].y],
                self.cur.right_px[a],
            ];
        }
        super::motion::to_corrected(rig, &mut self.quad_obs[..nq]);
        let seed = self.epoch;
        if check_motion(
            rig,
            mc,
            &self.quad_obs[..nq],
            self.quad_pts,
            self.quad_inlier,
            seed,
        )
        .is_none()
        {
            return nq;
        }
        let mut k = 0;
        for i in 0..nq {
            if self.quad_inlier[i] != 0 {
                self.quads[k] = self.quads[i];
                k += 1;
            }
        }
        stats.motion_outliers = (nq - k) as u32;
        k
    }

    fn accept_epoch(&mut self) {
        if self.has_prev {
            self.epoch = self.epoch.wrapping_add(1);
        }
        self.has_prev = true;
        self.stereo_in_cur = false;
        core::mem::swap(&mut self.prev, &mut self.cur);
    }

    /// After an accepted epoch: the previous epoch's stereo matches whose left keypoint
    /// the left temporal pass found again, as (previous left pixel, previous right
    /// pixel, current left keypoint index). Unlike the tie points, these need no closed
    /// quad: the material of a relocalization when the quads are too few.
    pub fn temporal_stereo<'s>(
        &'s self,
        prev_left: &'s [crate::features::Keypoint],
    ) -> impl Iterator<Item = ([f32; 2], [f32; 2], u32)> + 's {
        // After `accept_epoch`, the previous epoch's stereo results are in `cur`.
        let side = &self.cur;
        let n = side
            .n_left
            .min(prev_left.len())
            .min(self.left_temporal.len());
        (0..n).filter_map(move |i| {
            let c = self.left_temporal[i];
            (side.right_of[i] != NONE && c != NONE)
                .then(|| ([prev_left[i].x, prev_left[i].y], side.right_px[i], c))
        })
    }

    /// After an accepted epoch: every previous left keypoint (of the first `n_prev`) that
    /// the left temporal pass found again, as (previous index, current index), stereo
    /// match or not: the material of a rotation when even the relocalization fails.
    pub fn temporal_left(&self, n_prev: usize) -> impl Iterator<Item = (usize, u32)> + '_ {
        let n = n_prev.min(self.left_temporal.len());
        (0..n).filter_map(move |i| {
            let c = self.left_temporal[i];
            (c != NONE).then_some((i, c))
        })
    }

    /// The tie points of the last accepted epoch.
    pub fn tie_points(&self) -> impl Iterator<Item = TiePoint> + '_ {
        let epoch = self.epoch;
        self.quads[..self.n_tie].iter().filter_map(move |q| {
            let t = self.tracks.slots().get(q.track as usize)?;
            Some(TiePoint {
                track_id: t.id,
                slot: q.track,
                length: t.length,
                prev: self.tracks.observation(q.track, epoch.wrapping_sub(1))?,
                cur: self.tracks.observation(q.track, epoch)?,
            })
        })
    }

    /// Replaces the current-epoch positions of the tie point in track `slot` (after a
    /// refinement the matcher cannot do, e.g. against the previous epoch's image), with
    /// the right position's precision.
    pub fn refine_tie_point(&mut self, slot: u32, px: StereoPx) -> bool {
        let o = Observation {
            epoch: self.epoch,
            left: px.left,
            right: px.right,
            right_sigma: px.right_sigma,
        };
        self.tracks.set_observation(slot, o)
    }

    /// A fresh tie point identity (see `Tracks::allocate_id`).
    pub fn new_track_id(&mut self) -> u32 {
        self.tracks.allocate_id()
    }

    /// The quads of the last accepted epoch (keypoint indices of the four images).
    pub fn quads(&self) -> &[Quad] {
        &self.quads[..self.n_tie]
    }
}

/// FNV-1a over the keypoint positions and counts: detects a `prev` argument that is not
/// the epoch the stored stereo results belong to, in O(n) without keeping a copy.
fn fingerprint(pair: &StereoFeatures<'_>, cap: usize) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |v: u32| {
        h ^= v as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    };
    for f in [pair.left, pair.right] {
        let n = f.usable(cap);
        eat(n as u32);
        for k in &f.keypoints[..n] {
            eat(k.x.to_bits());
            eat(k.y.to_bits());
        }
    }
    h
}
