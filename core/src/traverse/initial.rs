//! Initial values of an epoch's pose: robust resection on tie points already in object
//! space, relocalisation, and the rotation from the matches when the resection fails.
use super::*;

impl Traverse<'_> {
    /// Robust resection of the current left camera on tie points already in the window.
    pub(super) fn resect(&mut self) -> Option<Pose> {
        let mut n = 0;
        for tie in self.matcher.tie_points() {
            if n >= self.corr.len() {
                break;
            }
            let Some(point) = known_point(self.track_points, &self.window, &tie) else {
                continue;
            };
            let Some(xyz) = self.window.point(point) else {
                continue;
            };
            let [c, r] = tie.cur.left;
            let xy = self.cfg.rig.left.pixel_to_corrected(c as f64, r as f64);
            self.corr[n] = Correspondence { point: xyz, xy };
            n += 1;
        }
        self.resect_on(n, self.cfg.min_tie_points)
    }

    /// Robust resection of the current left camera on the first `n` correspondences;
    /// a pose only with at least `min_inliers` inliers.
    fn resect_on(&self, n: usize, min_inliers: usize) -> Option<Pose> {
        let mut rcfg = self.cfg.resection;
        rcfg.threshold_mm = 3.0 * self.cfg.sigma_px * self.cfg.rig.left.pixel_size_mm[0];
        rcfg.min_inliers = min_inliers;
        let r = resect(&self.corr[..n], self.cfg.rig.left.focal_mm, &rcfg).ok()?;
        (r.inliers >= min_inliers).then_some(r.pose)
    }

    /// Resection of the current left camera on the previous stereo pair's points that
    /// the temporal matching found again, quads or not (`Matcher::temporal_stereo`):
    /// when the motion prediction was wrong (the onset of a turn, a jolt), the guided
    /// search closes few quads, but the fallback search still pairs many keypoints.
    /// The points are intersected from the previous window epoch's pose.
    pub(super) fn relocalize(&mut self) -> Option<Pose> {
        let last = self.window.n_epochs().checked_sub(1)?;
        let prev_left = self.window.epoch_pose(last)?;
        let prev = [prev_left, self.right_of(&prev_left)];
        let rig = self.rig_now();
        let cur = self.features[self.cur][0].keypoints();
        let prev_kps = self.features[1 - self.cur][0].keypoints();
        let mut n = 0;
        for (pl, pr, c) in self.matcher.temporal_stereo(prev_kps) {
            if n >= self.corr.len() {
                break;
            }
            let (Some(k), Some(xyz)) = (
                cur.get(c as usize),
                intersect_pair(&self.cfg, &rig, &prev, pl, pr),
            ) else {
                continue;
            };
            let xy = self.cfg.rig.left.pixel_to_corrected(k.x as f64, k.y as f64);
            self.corr[n] = Correspondence { point: xyz, xy };
            n += 1;
        }
        self.resect_on(n, config::RELOCALIZATION_MIN_INLIERS)
    }

    /// The prediction with its rotation found from the left temporal matches
    /// ([`turn::robust_rotation`]), when they agree on one: the previous left keypoints'
    /// rays from the previous window epoch's pose against the current keypoints' rays.
    pub(super) fn rotation_from_matches(&mut self, prediction: &Pose) -> Option<Pose> {
        let last = self.window.n_epochs().checked_sub(1)?;
        let prev_pose = self.window.epoch_pose(last)?;
        let m_prev = prev_pose.rotation();
        let interior = self.cfg.rig.left;
        let f = interior.focal_mm;
        let cur = self.features[self.cur][0].keypoints();
        let prev_kps = self.features[1 - self.cur][0].keypoints();
        let mut n = 0;
        for (p, c) in self.matcher.temporal_left(prev_kps.len()) {
            if n >= self.corr.len() {
                break;
            }
            let (Some(q), Some(k)) = (prev_kps.get(p), cur.get(c as usize)) else {
                continue;
            };
            let [x, y] = interior.pixel_to_corrected(q.x as f64, q.y as f64);
            let ray = m_prev.transpose() * Vector3::new(x, y, -f).normalize();
            let xy = interior.pixel_to_corrected(k.x as f64, k.y as f64);
            self.corr[n] = Correspondence {
                point: [ray[0], ray[1], ray[2]],
                xy,
            };
            n += 1;
        }
        let px = 0.5 * (interior.pixel_size_mm[0] + interior.pixel_size_mm[1]);
        let tcfg = turn::TurnConfig {
            threshold_rad: config::TURN_THRESHOLD_PX * px / f,
            min_inliers: config::RELOCALIZATION_MIN_INLIERS,
            samples: config::TURN_SAMPLES,
        };
        let corr = &self.corr[..n];
        let (r, k) = turn::robust_rotation(corr, f, &tcfg)?;
        // Only a rotation that explains far more matches than the prediction's replaces
        // it: where a moving vehicle fills the image, its matches agree on a rotation of
        // their own, while the prediction's still explains the static scene.
        let k_pred = turn::inliers(corr, f, tcfg.threshold_rad, &prediction.rotation());
        if k < config::TURN_MIN_GAIN * k_pred {
            return None;
        }
        let [omega, phi, kappa] = angles_from_rotation(&r);
        Some(Pose {
            omega,
            phi,
            kappa,
            centre: prediction.centre,
        })
    }
}
