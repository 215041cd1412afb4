//! What the window holds after a solution: poses, points, their covariances (relative to
//! the fixed past and with respect to the datum), residuals and the rig.
use super::*;

impl<'a> Window<'a> {
    pub fn n_epochs(&self) -> usize {
        self.n_epochs
    }

    /// Id of the epoch in slot `i` (0 = oldest).
    pub fn epoch_id(&self, i: usize) -> Option<u32> {
        (i < self.n_epochs).then(|| self.epochs[i].id)
    }

    /// Adjusted (or current) pose of the left camera of slot `i`, object coordinates.
    pub fn epoch_pose(&self, i: usize) -> Option<Pose> {
        if i >= self.n_epochs {
            return None;
        }
        let mut p = self.epochs[i].params;
        for a in 0..3 {
            p[3 + a] += self.origin[a];
        }
        Some(Pose::from_params(&p))
    }

    /// Standard deviations of slot `i` (omega, phi, kappa rad; X, Y, Z m) from the last solution.
    pub fn epoch_std(&self, i: usize) -> Option<[f64; 6]> {
        Some(standard_deviations(&self.epoch_covariance(i)?))
    }

    /// 6x6 covariance of slot `i` with respect to the datum (row-major; omega, phi,
    /// kappa rad, X, Y, Z m): [`Self::absolute_turn_covariance`] in the angles.
    pub fn epoch_absolute_covariance(&self, i: usize) -> Option<[f64; 36]> {
        Some(attitude::to_angles(
            &self.epochs[i].params,
            &self.absolute_turn_covariance(i)?,
        ))
    }

    /// Slot `i`'s covariance with respect to the datum, in the window's unknowns (turn
    /// and centre). The window's own covariance ([`Self::turn_covariance`]) holds the
    /// fixed epochs exact, so it is the precision relative to the poses that left; the
    /// newest fixed epoch's absolute covariance, carried rigidly to the epoch (its
    /// rotation error turns the epoch's offset from it), adds what they were uncertain
    /// by. Each fixed epoch keeps the absolute covariance it left with, so the
    /// uncertainty of a traverse without fixes accumulates step by step, as it should.
    ///
    /// A leaving (oldest) epoch keeps it as a fixed epoch. Only the window's part is
    /// scaled, to no less than its a-priori value (sigma0 = 1): the anchor's was, at
    /// its slide (scaling the sum compounded the scale at every slide). The
    /// a-posteriori scale comes from residuals that do not see the errors a traverse
    /// accumulates, which are correlated from epoch to epoch (the same points on the
    /// same surfaces), so below 1 it makes the precision optimistic. A window anchored
    /// by GNSS fixes has no fixed epochs, and there its part is the whole: at the
    /// solutions' sigma0 (about 0.2) the angles' standard deviations were about 3 times
    /// too small, and 57 % of the epochs of 63 rendered aided runs had an angle past 3
    /// of them (`bench/aiding/README.md`, 2026-12-07).
    pub(super) fn absolute_turn_covariance(&self, i: usize) -> Option<[f64; 36]> {
        let k = self.apriori_floor();
        let cov = self.turn_covariance(i)?.map(|v| v * k);
        Some(self.plus_anchor(i, cov))
    }

    /// `cov` (of slot `i`, relative to the fixed epochs) plus the newest fixed epoch's
    /// absolute covariance carried rigidly to the slot: `cov + J C_a J^T`, in the
    /// window's unknowns (turn and centre), in which the slots keep their covariances.
    pub(super) fn plus_anchor(&self, i: usize, mut cov: [f64; 36]) -> [f64; 36] {
        let Some(anchor) = self.n_fixed.checked_sub(1).map(|a| &self.fixed[a]) else {
            return cov;
        };
        let j = rigid_transport_turn(&anchor.params, &self.epochs[i].params);
        let carried = propagate(&j, &anchor.cov);
        for (c, a) in cov.iter_mut().zip(carried) {
            *c += a;
        }
        cov
    }

    /// The factor that raises the last solution's covariances to no less than their
    /// a-priori value: `1 / sigma0^2` when sigma0 is below 1, else 1.
    pub(super) fn apriori_floor(&self) -> f64 {
        if self.cov_s02 > 0.0 && self.cov_s02 < 1.0 {
            1.0 / self.cov_s02
        } else {
            1.0
        }
    }

    /// Standard deviations of slot `i` relative to the recent past (the fixed epochs held
    /// exact), at no less than their a-priori value, as a fixed epoch keeps them
    /// ([`Self::absolute_turn_covariance`]): what a difference of neighbouring epochs is
    /// uncertain by.
    pub fn epoch_relative_std(&self, i: usize) -> Option<[f64; 6]> {
        let k = libm::sqrt(self.apriori_floor());
        Some(self.epoch_std(i)?.map(|v| v * k))
    }

    /// Standard deviations of slot `i` with respect to the datum (omega, phi, kappa
    /// rad; X, Y, Z m): [`Self::epoch_absolute_covariance`].
    pub fn epoch_absolute_std(&self, i: usize) -> Option<[f64; 6]> {
        Some(standard_deviations(&self.epoch_absolute_covariance(i)?))
    }

    /// 6x6 covariance (row-major; omega, phi, kappa rad, X, Y, Z m) of slot `i` from
    /// the last solution (sigma0^2 scaled).
    pub fn epoch_covariance(&self, i: usize) -> Option<[f64; 36]> {
        let cov = self.turn_covariance(i)?;
        Some(attitude::to_angles(&self.epochs[i].params, &cov))
    }

    /// [`Self::epoch_covariance`] in the window's unknowns (turn and centre).
    pub(super) fn turn_covariance(&self, i: usize) -> Option<[f64; 36]> {
        (i < self.n_epochs && self.epochs[i].flags & EP_COV != 0).then(|| self.epochs[i].cov)
    }

    /// Adjusted point in object coordinates; `None` when unknown or excluded.
    pub fn point(&self, point: u32) -> Option<[f64; 3]> {
        let p = self.point_slot(point).ok()?;
        let s = &self.points[p];
        if s.flags & PT_EXCLUDED != 0 {
            return None;
        }
        Some([
            s.xyz[0] + self.origin[0],
            s.xyz[1] + self.origin[1],
            s.xyz[2] + self.origin[2],
        ])
    }

    /// Ids of the points the window holds (with an observation or a prior), excluded
    /// ones included: the slots of [`AdjustConfig::max_points`] in use.
    pub fn point_ids(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.n_point_slots)
            .filter(|&p| self.points[p].flags & PT_USED != 0)
            .map(|p| p as u32)
    }

    /// Standard deviations of a point, metres.
    pub fn point_std(&self, point: u32) -> Option<[f64; 3]> {
        let p = self.point_slot(point).ok()?;
        (self.points[p].flags & PT_EXCLUDED == 0).then(|| self.points[p].std)
    }

    /// Whether a point was left out of the last solution.
    pub fn point_excluded(&self, point: u32) -> bool {
        self.point_slot(point)
            .map(|p| self.points[p].flags & PT_EXCLUDED != 0)
            .unwrap_or(true)
    }

    pub fn rig(&self) -> RelativeOrientation {
        self.rig
    }

    /// Standard deviations of the rig parameters: of the last estimate, zero when the
    /// rig was never estimated.
    pub fn rig_std(&self) -> [f64; 6] {
        self.rig_std
    }

    /// Interior orientation corrections `[x0_L, y0_L, f_L, x0_R, y0_R, f_R]` (mm)
    /// found by the self-calibration (zero without it).
    pub fn interior(&self) -> InteriorCorrections {
        self.interior
    }

    /// `calibration` (the rig the window was built with) as the window has it now: its
    /// relative orientation and the interior corrections applied, each camera's
    /// principal point and focal length moved by its own (see [`InteriorCorrections`]).
    /// The lens distortion stays the calibration's.
    pub fn adjusted_rig(&self, calibration: &Rig) -> Rig {
        let mut rig = *calibration;
        rig.relative_angles = self.rig.angles;
        rig.base_m = self.rig.base;
        let focal = [calibration.left.focal_mm, calibration.right.focal_mm];
        for (camera, interior) in [
            (Camera::Left, &mut rig.left),
            (Camera::Right, &mut rig.right),
        ] {
            interior.principal_point_mm =
                shift_principal_point(interior.principal_point_mm, camera, &self.interior);
            interior.focal_mm = corrected_focal(focal, camera, &self.interior);
        }
        rig
    }

    /// Standard deviations of [`Self::interior`] (zero without self-calibration).
    pub fn interior_std(&self) -> [f64; 6] {
        self.interior_std
    }

    pub fn observations(&self) -> &[Observation] {
        &self.obs[..self.n_obs]
    }

    /// Indices (into [`Window::observations`]) of point slot `p`'s observations, from
    /// the index of the last adjustment; `None` when observations came or went since.
    pub fn point_observations(&self, p: u32) -> Option<&[u32]> {
        let p = p as usize;
        if !self.indexed.is_some_and(|np| p < np) {
            return None;
        }
        let (s0, s1) = (
            self.point_start[p] as usize,
            self.point_start[p + 1] as usize,
        );
        self.obs_order.get(s0..s1)
    }

    /// Observations flagged as blunders, with their indices.
    pub fn flagged(&self) -> impl Iterator<Item = (usize, &Observation)> {
        self.observations()
            .iter()
            .enumerate()
            .filter(|(_, o)| o.is_flagged())
    }

    /// Residuals `observed - computed` (mm) of an observation at the current state.
    pub fn residual(&self, index: usize) -> Option<[f64; 2]> {
        let o = self.obs.get(index).filter(|_| index < self.n_obs)?;
        let at = self.locate(o.epoch)?;
        let p = self.params_at(at);
        let ml = crate::camera::rotation(p[0], p[1], p[2]);
        self.residual_with(o, &ml, &p, &self.rig_rotation())
    }

    /// [`Self::residual`] of every observation in order: the rotations computed once
    /// per epoch's run of observations rather than once per observation.
    pub fn residuals(&self) -> impl Iterator<Item = Option<[f64; 2]>> + '_ {
        let mr = self.rig_rotation();
        let mut last: Option<(u32, Matrix3<f64>, [f64; 6])> = None;
        self.obs[..self.n_obs].iter().map(move |o| {
            let (ml, p) = match last {
                Some((e, ml, p)) if e == o.epoch => (ml, p),
                _ => {
                    let p = self.params_at(self.locate(o.epoch)?);
                    let ml = crate::camera::rotation(p[0], p[1], p[2]);
                    last = Some((o.epoch, ml, p));
                    (ml, p)
                }
            };
            self.residual_with(o, &ml, &p, &mr)
        })
    }

    /// The rig's relative rotation `M` from its current angles.
    pub(super) fn rig_rotation(&self) -> Matrix3<f64> {
        let a = self.rig.angles;
        crate::camera::rotation(a[0], a[1], a[2])
    }

    /// Residual of `o` with its epoch's rotation `ml` and parameters `p`, the rig's `mr`.
    pub(super) fn residual_with(
        &self,
        o: &Observation,
        ml: &Matrix3<f64>,
        p: &[f64; 6],
        mr: &Matrix3<f64>,
    ) -> Option<[f64; 2]> {
        let cam = Camera::from_index(o.camera)?;
        let f = corrected_focal(self.focal, cam, &self.interior);
        let point = &self.points[o.point as usize].xyz;
        let centre = [p[3], p[4], p[5]];
        let xy = project_xy_with(ml, &centre, mr, &self.rig.base, cam, f, point)?;
        let xy = shift_principal_point(xy, cam, &self.interior);
        Some([o.xy[0] as f64 - xy[0], o.xy[1] as f64 - xy[1]])
    }

    /// Items refused because a capacity was full: (points, observations).
    pub fn dropped(&self) -> (usize, usize) {
        (self.dropped_points, self.dropped_observations)
    }

    /// Slot of the epoch found undetermined by the last failed solution.
    pub fn singular_epoch(&self) -> Option<usize> {
        self.singular_epoch
    }

    /// The window's local origin (object coordinates).
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }

    // ----- sliding -----
}
