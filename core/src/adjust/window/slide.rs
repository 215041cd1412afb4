//! Sliding: the leaving epoch becomes fixed (or, with GNSS fixes, is released with the
//! fixed past), the new first epoch gets the carried prior, the origin moves.
use super::*;

impl<'a> Window<'a> {
    /// Drops the oldest epoch (fixed at its current pose). With
    /// [`AdjustConfig::fixed_epochs`], its observations stay while their points are
    /// observed in the window, so a point keeps what every epoch of its track told
    /// about it (the poses that left are fixed: their observations constrain the
    /// points only), and the oldest fixed epoch's observations leave in its place;
    /// without, its observations leave with it. Points left without an observation
    /// in the window are freed, and the new oldest epoch gets its current pose and
    /// covariance as a prior. The origin moves to the new oldest epoch. Returns the
    /// dropped epoch's final pose.
    pub fn slide(&mut self) -> Result<Pose, AdjustError> {
        if self.n_epochs < 2 {
            return Err(AdjustError::TooFewEpochs);
        }
        let dropped = self.epoch_pose(0).ok_or(AdjustError::TooFewEpochs)?;
        let gone = self.epochs[0].id;
        // A GNSS fix, not the poses of the past held exact, anchors an aided window:
        // an epoch with a fix leaves without becoming a fixed epoch and releases those
        // there are, or the window could not follow the fixes (it would carry the
        // past's drift forward, the fixes pulling at it only by their weight).
        let aided = self.epochs[0].flags & EP_GNSS != 0;
        let had_fixed = self.n_fixed > 0;
        let cap = if aided { 0 } else { self.cfg.fixed_epochs };
        let expired = if cap == 0 {
            Some(gone)
        } else {
            let e = &self.epochs[0];
            let rot = Rotations::with_turn(e.params[0], e.params[1], e.params[2]);
            let slot = FixedSlot {
                params: e.params,
                rot,
                right: right_rotation(&rot, &self.rig_rot),
                time: e.time,
                // Without a covariance of its own (its solve failed) it passes the
                // anchor's on: the accumulated uncertainty is not lost.
                cov: self
                    .absolute_turn_covariance(0)
                    .unwrap_or_else(|| self.plus_anchor(0, [0.0; 36])),
            };
            let expired = (self.n_fixed == cap).then(|| gone.wrapping_sub(cap as u32));
            if self.n_fixed == cap {
                self.fixed.copy_within(1..cap, 0);
                self.n_fixed -= 1;
            }
            self.fixed[self.n_fixed] = slot;
            self.n_fixed += 1;
            expired
        };
        let release = aided && had_fixed;
        // What the past tells about the new first epoch, taken while the fixed epochs
        // that are about to go still anchor it.
        let released_info = if release {
            self.carried_information(1, true)
        } else {
            None
        };
        // Observations in the window per point, after this slide (point_start is
        // scratch until the next build_index).
        let np = self.n_point_slots;
        self.point_start[..np].fill(0);
        for o in &self.obs[..self.n_obs] {
            if o.epoch != gone && self.slot_of(o.epoch).is_some() {
                self.point_start[o.point as usize] += 1;
            }
        }
        self.retain_observations(|w, o| {
            let released = release && w.slot_of(o.epoch).is_none();
            Some(o.epoch) != expired && !released && w.point_start[o.point as usize] > 0
        });
        if release {
            self.n_fixed = 0;
        }
        // Prior of the new first epoch from its marginal covariance.
        let aided_info = if aided && released_info.is_none() {
            self.carried_information(1, false)
        } else {
            None
        };
        let next = &mut self.epochs[1];
        let mut info = [0.0; 36];
        let have = match released_info.or(aided_info) {
            // The window's only link to the epochs that left, at full strength.
            Some(carried) => {
                info = carried;
                true
            }
            None => {
                let have = next.flags & EP_COV != 0 && invert6(&next.cov, &mut info);
                if have && self.cfg.fixed_epochs > 0 {
                    // The marginal holds the fixed epochs' observations, which stay:
                    // weakened.
                    let k = 1.0 / self.cfg.carried_prior_inflation;
                    info.iter_mut().for_each(|v| *v *= k);
                }
                have
            }
        };
        if !have {
            info = self.cfg.sigmas.datum_information();
        }
        next.prior = next.params;
        next.prior_info = info;
        next.flags |= EP_PRIOR;
        // Its odometer leg led to the dropped epoch.
        next.flags &= !EP_ODOMETER;
        self.carry_rig_prior();
        self.epochs.copy_within(1..self.n_epochs, 0);
        self.n_epochs -= 1;
        self.first_id += 1;
        let shift = [
            self.epochs[0].params[3],
            self.epochs[0].params[4],
            self.epochs[0].params[5],
        ];
        self.recentre(shift);
        Ok(dropped)
    }

    /// The rig is shared by every epoch: a slide keeps its value, and what the
    /// dropped epoch told about it stays in its prior. The marginal information
    /// `inv(Q_rig)` is the prior's plus the window's observations'; the dropped
    /// epoch's share is taken as `1/n` of the latter, so the prior grows by one
    /// epoch's worth per slide (carrying the whole marginal would count the
    /// remaining epochs' observations again at every slide and make the rig
    /// overconfident). Uses `Q` without sigma0, like the calibration prior.
    /// The interior orientation corrections are carried the same way.
    pub(super) fn carry_rig_prior(&mut self) {
        if !self.rig_cov_valid {
            return;
        }
        let n = self.n_epochs.max(1) as f64;
        if self.cfg.estimate_rig {
            let mut prior = self.rig_prior.to_array();
            carry_prior(
                &self.rig.to_array(),
                &self.rig_cov,
                n,
                &mut prior,
                &mut self.rig_prior_info,
            );
            self.rig_prior = RelativeOrientation::from_array(&prior);
        }
        if self.cfg.self_calibration.is_some() {
            carry_prior(
                &self.interior,
                &self.interior_cov,
                n,
                &mut self.interior_prior,
                &mut self.interior_prior_info,
            );
        }
        self.rig_cov_valid = false;
    }

    /// Keeps the observations `keep` accepts, in order; a point left without one (and
    /// without a prior) is freed.
    pub(super) fn retain_observations(&mut self, keep: impl Fn(&Self, &Observation) -> bool) {
        let mut k = 0;
        for i in 0..self.n_obs {
            let o = self.obs[i];
            if keep(self, &o) {
                self.obs[k] = o;
                k += 1;
            } else {
                let p = &mut self.points[o.point as usize];
                p.nobs = p.nobs.saturating_sub(1);
                if p.nobs == 0 && p.flags & PT_PRIOR == 0 {
                    p.flags = 0;
                }
            }
        }
        self.n_obs = k;
        self.indexed = None;
    }

    /// Lets go of the fixed epochs: their observations leave, and the window's link to
    /// the past is its first epoch's prior alone.
    pub(super) fn release_fixed(&mut self) {
        if self.n_fixed == 0 {
            return;
        }
        // The first epoch's prior, weak while the fixed epochs anchored the window,
        // becomes what they told about it: its covariance with respect to the datum.
        if let Some(info) = self.carried_information(0, true) {
            let e = &mut self.epochs[0];
            e.prior = e.params;
            e.prior_info = info;
            e.flags |= EP_PRIOR;
        }
        self.retain_observations(|w, o| w.slot_of(o.epoch).is_some());
        self.n_fixed = 0;
    }

    /// The information of a prior carried on slot `i` when the window is anchored by
    /// fixes: the slot's covariance in the a-priori units of the fixes' weights (the
    /// solution's is `sigma0^2 Q`; the prior is `Q^-1`), with the newest fixed epoch's
    /// absolute covariance added when `with_anchor` (the fixed epochs are about to go),
    /// less the slot's own fix, which stays in the window (`J^T W J`; kept only if the
    /// rest is still positive definite). `None` without a covariance.
    pub(super) fn carried_information(&self, i: usize, with_anchor: bool) -> Option<[f64; 36]> {
        let e = &self.epochs[i];
        if e.flags & EP_COV == 0 || !(self.cov_s02 > 0.0) {
            return None;
        }
        let mut cov = e.cov.map(|v| v / self.cov_s02);
        if with_anchor {
            cov = self.plus_anchor(i, cov);
        }
        let mut info = [0.0; 36];
        if !invert6(&cov, &mut info) {
            return None;
        }
        if e.flags & EP_GNSS != 0 {
            let w = 1.0 / (e.gnss_sigma * e.gnss_sigma);
            let (_, j) = gnss_residual(e);
            let mut less = info;
            for r in 0..6 {
                for c in 0..6 {
                    let jtj: f64 = (0..3).map(|a| j[a][r] * j[a][c]).sum();
                    less[r * 6 + c] -= w * jtj;
                }
            }
            let mut check = [0.0; 36];
            if invert6(&less, &mut check) {
                info = less;
            }
        }
        Some(info)
    }

    /// Moves the local origin by `shift` (local coordinates).
    pub(super) fn recentre(&mut self, shift: [f64; 3]) {
        for a in 0..3 {
            self.origin[a] += shift[a];
        }
        for e in self.epochs[..self.n_epochs].iter_mut() {
            for a in 0..3 {
                e.params[3 + a] -= shift[a];
                e.prior[3 + a] -= shift[a];
                e.gnss[a] -= shift[a];
            }
        }
        for f in self.fixed[..self.n_fixed].iter_mut() {
            for a in 0..3 {
                f.params[3 + a] -= shift[a];
            }
        }
        for p in self.points[..self.n_point_slots].iter_mut() {
            for a in 0..3 {
                p.xyz[a] -= shift[a];
                p.prior[a] -= shift[a];
            }
        }
    }

    // ----- the solver -----
}
