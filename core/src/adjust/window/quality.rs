//! Quality: the global test, the statistics of a solution, and the test and correction
//! of the calibration (rig and interior orientation).
use super::*;

impl<'a> Window<'a> {
    /// `T` of observation `oi` (0 when untestable).
    pub(super) fn statistic(&self, oi: usize, vinv: Option<&Matrix3<f64>>, all: bool) -> f64 {
        let o = &self.obs[oi];
        let Some(vinv) = vinv else { return 0.0 };
        let Some(at) = self.locate(o.epoch) else {
            return 0.0;
        };
        let cam = if o.camera == 0 {
            Camera::Left
        } else {
            Camera::Right
        };
        let xyz = self.points[o.point as usize].xyz;
        let Ok(pr) = self.project(at, cam, &xyz, Partials::Point) else {
            return f64::INFINITY;
        };
        let r = [o.xy[0] as f64 - pr.xy[0], o.xy[1] as f64 - pr.xy[1]];
        let j = nalgebra::Matrix2x3::new(
            pr.d_point[0][0],
            pr.d_point[0][1],
            pr.d_point[0][2],
            pr.d_point[1][0],
            pr.d_point[1][1],
            pr.d_point[1][2],
        );
        let jq = j * vinv * j.transpose();
        let sign = if o.factor > 0.0 || all { -1.0 } else { 1.0 };
        let ow = o.weights();
        let q = nalgebra::Matrix2::new(1.0 / ow[0], 0.0, 0.0, 1.0 / ow[1]) + jq * sign;
        // Untestable when the observation carries (almost) no redundancy.
        if !(q[(0, 0)] > 1e-3 / ow[0]) || !(q[(1, 1)] > 1e-3 / ow[1]) {
            return 0.0;
        }
        match q.try_inverse() {
            Some(qi) => {
                let v = nalgebra::Vector2::new(r[0], r[1]);
                (v.transpose() * qi * v)[0].max(0.0)
            }
            None => 0.0,
        }
    }

    /// sigma0, chi-square, redundancy, and standard deviations from the inverse
    /// of the undamped reduced normal matrix (scaled by sigma0^2).
    /// Counts, redundancy, sigma0 and the global chi-square test of the current
    /// solution into `report`; returns the variance factor.
    pub(super) fn global_test(&mut self, report: &mut Report) -> Result<f64, AdjustError> {
        let nc = if self.calibration_held {
            6 * self.n_epochs
        } else {
            self.n_cam()
        };
        let (obs_cost, behind) = self.cost();
        let (_, n_constraints) = self.add_constraints(false);
        let mut n_obs = 0;
        let mut n_points = 0;
        let mut n_point_priors = 0;
        let mut excluded = 0;
        for p in 0..self.n_point_slots {
            let pt = self.points[p];
            if pt.flags & PT_USED == 0 {
                continue;
            }
            if pt.flags & PT_EXCLUDED != 0 {
                excluded += 1;
                continue;
            }
            n_points += 1;
            if pt.flags & PT_PRIOR != 0 {
                n_point_priors += 3;
            }
            let (s0, s1) = (
                self.point_start[p] as usize,
                self.point_start[p + 1] as usize,
            );
            for k in s0..s1 {
                let o = &self.obs[self.obs_order[k] as usize];
                if o.factor > 0.0
                    && o.flags & Observation::BEHIND == 0
                    && self.locate(o.epoch).is_some()
                {
                    n_obs += 1;
                }
            }
        }
        let equations = 2 * n_obs + n_constraints + n_point_priors;
        let unknowns = nc + 3 * n_points;
        report.observations = n_obs;
        report.constraints = n_constraints + n_point_priors;
        report.unknowns = unknowns;
        report.behind = behind;
        report.excluded_points = excluded;
        report.cost = obs_cost;
        report.flagged = self.obs[..self.n_obs]
            .iter()
            .filter(|o| o.is_flagged())
            .count();
        if equations <= unknowns {
            return Err(AdjustError::NoRedundancy);
        }
        let dof = equations - unknowns;
        report.redundancy = dof;
        let s02 = obs_cost / dof as f64;
        report.sigma0 = libm::sqrt(s02);
        report.chi2 = ChiSquareTest::new(obs_cost, dof);
        Ok(s02)
    }

    /// [`Self::global_test`], then the precisions: camera, rig and interior covariances
    /// and the points' standard deviations.
    pub(super) fn quality(&mut self, report: &mut Report) -> Result<(), AdjustError> {
        let s02 = self.global_test(report)?;
        self.cov_s02 = s02;
        let nc = self.n_cam();
        let rig_block = self.rig_block();
        // Undamped reduced matrix, inverted in place: Q_cc.
        self.step_matrix_only()?;
        cholesky::invert_in_place(&mut self.reduced[..nc * nc], nc);
        self.clear_held_cofactors();
        for e in 0..self.n_epochs {
            let mut cov = [0.0; 36];
            for i in 0..6 {
                for j in 0..6 {
                    cov[i * 6 + j] = s02 * self.reduced[(6 * e + i) * nc + 6 * e + j];
                }
            }
            self.epochs[e].cov = cov;
            self.epochs[e].flags |= EP_COV;
        }
        if let Some(rb) = rig_block.filter(|_| !self.calibration_held) {
            for i in 0..6 {
                for j in 0..6 {
                    self.rig_cov[i * 6 + j] = self.reduced[(6 * rb + i) * nc + 6 * rb + j];
                }
                self.rig_std[i] = libm::sqrt((s02 * self.rig_cov[i * 6 + i]).max(0.0));
            }
        }
        if let Some(ib) = self.interior_block().filter(|_| !self.calibration_held) {
            for i in 0..6 {
                for j in 0..6 {
                    self.interior_cov[i * 6 + j] = self.reduced[(6 * ib + i) * nc + 6 * ib + j];
                }
                self.interior_std[i] = libm::sqrt((s02 * self.interior_cov[i * 6 + i]).max(0.0));
            }
        }
        // A held calibration has no estimate to carry across the slide.
        self.rig_cov_valid = !self.calibration_held;
        // Points: Q_pp = V^-1 + V^-1 W^T Q_cc W V^-1.
        for p in 0..self.n_point_slots {
            if self.points[p].flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            let (pb, _, _) = self.point_blocks(p, CamBlocks::Cross);
            let Some(vinv) = sym3_inverse(&pb.v) else {
                continue;
            };
            let mut q = vinv;
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let ga = nalgebra::Matrix6x3::from_row_slice(&self.scratch[a].w) * vinv;
                for tj in 0..pb.touched {
                    let b = self.touched[tj] as usize;
                    let bb = self.block_of(b);
                    let gb = nalgebra::Matrix6x3::from_row_slice(&self.scratch[b].w) * vinv;
                    let qab = nalgebra::Matrix6::from_fn(|i, j| {
                        self.reduced[(6 * ba + i) * nc + 6 * bb + j]
                    });
                    q += ga.transpose() * qab * gb;
                }
            }
            for i in 0..3 {
                self.points[p].std[i] = libm::sqrt((s02 * q[(i, i)]).max(0.0));
            }
        }
        Ok(())
    }

    /// A held calibration is known, not estimated: its rows and columns of the inverted
    /// reduced matrix (the unit placeholders of [`Self::hold_blocks`]) add nothing to
    /// the points' cofactors.
    pub(super) fn clear_held_cofactors(&mut self) {
        if !self.calibration_held {
            return;
        }
        let nc = self.n_cam();
        for r in 6 * self.n_epochs..nc {
            for c in 0..nc {
                self.reduced[r * nc + c] = 0.0;
                self.reduced[c * nc + r] = 0.0;
            }
        }
    }

    /// The score test of the held calibration at the current solution (call it after
    /// [`Self::solve`]; `sigma0` is that solution's a-posteriori standard deviation).
    ///
    /// Why a score test: it needs no adjustment with the calibration free, so a good
    /// calibration is never disturbed by its own estimation. At the held solution the
    /// poses' and points' gradient is zero, so the full system's step `d = N^-1 g` is
    /// the free adjustment's first step in the calibration and `d_c^T g_c` (the
    /// calibration's part) is `g_red^T N_red^-1 g_red`, the Schur complement's quadratic
    /// form: the statistic. The calibration priors are part of `N` and `g`, so a
    /// correction is weighed against the calibration's stated precision.
    pub fn calibration_test(&mut self, sigma0: f64) -> Result<CalibrationTest, AdjustError> {
        let first = 6 * self.n_epochs;
        let nc = self.n_cam();
        if !self.calibration_held || nc == first {
            return Err(AdjustError::InvalidConfig);
        }
        self.build_index();
        self.testing_calibration = true;
        self.build(0.0);
        self.testing_calibration = false;
        let mut g = [0.0; 12];
        g[..nc - first].copy_from_slice(&self.rhs[first..nc]);
        cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL).map_err(
            |e| AdjustError::Singular {
                epoch: (e.row / 6).min(self.n_epochs.saturating_sub(1)),
            },
        )?;
        cholesky::solve(&self.reduced[..nc * nc], nc, &mut self.rhs[..nc]);
        let d = &self.rhs[first..nc];
        let score: f64 = d.iter().zip(&g).map(|(a, b)| a * b).sum();
        let s02 = (sigma0 * sigma0).max(1e-300);
        let mut test = CalibrationTest {
            statistic: score / s02,
            dof: nc - first,
            ..Default::default()
        };
        let mut at = first;
        if self.rig_block().is_some() {
            test.rig.copy_from_slice(&self.rhs[at..at + 6]);
            at += 6;
        }
        if self.interior_block().is_some() {
            test.interior.copy_from_slice(&self.rhs[at..at + 6]);
        }
        Ok(test)
    }

    /// How far the correction of `test` would move the observations of the window's
    /// newest epoch: the RMS displacement (mm, both cameras) of their projections
    /// with the corrected calibration against the held one. A correction the test
    /// finds significant may still be too small to matter: hundreds of points make a
    /// hundredth of a pixel of systematic matching error significant.
    pub fn correction_effect(&mut self, test: &CalibrationTest) -> f64 {
        let Some(last) = self.n_epochs.checked_sub(1) else {
            return 0.0;
        };
        self.refresh_rotations();
        let mut rig = self.rig.to_array();
        for (r, d) in rig.iter_mut().zip(test.rig) {
            *r += d;
        }
        let rig = RelativeOrientation::from_array(&rig);
        let rig_rot = Rotations::new(rig.angles[0], rig.angles[1], rig.angles[2]);
        let mut interior = self.interior;
        for (i, d) in interior.iter_mut().zip(test.interior) {
            *i += d;
        }
        let id = self.epochs[last].id;
        let (rot, c) = self.pose_parts(At::Window(last));
        let (mut sum, mut n) = (0.0, 0usize);
        for o in &self.obs[..self.n_obs] {
            let pt = &self.points[o.point as usize];
            if o.epoch != id || !(o.factor > 0.0) || pt.flags & PT_USED == 0 {
                continue;
            }
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            let project =
                |rig: &RelativeOrientation, rig_rot: &Rotations, interior: &InteriorCorrections| {
                    let f = corrected_focal(self.focal, cam, interior);
                    project_xy(rot.left, &c, rig_rot, &rig.base, cam, f, &pt.xyz)
                        .map(|xy| shift_principal_point(xy, cam, interior))
                };
            let before = project(&self.rig, &self.rig_rot, &self.interior);
            let after = project(&rig, &rig_rot, &interior);
            if let (Some(a), Some(b)) = (before, after) {
                sum += (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]);
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            libm::sqrt(sum / n as f64)
        }
    }

    /// Applies the correction of a [`CalibrationTest`] to the held calibration; the
    /// next [`Self::solve`] adjusts the poses and points to it.
    pub fn correct_calibration(&mut self, test: &CalibrationTest) {
        let mut r = self.rig.to_array();
        for (ri, d) in r.iter_mut().zip(test.rig) {
            *ri += d;
        }
        self.rig = RelativeOrientation::from_array(&r);
        for (i, d) in self.interior.iter_mut().zip(test.interior) {
            *i += d;
        }
    }

    /// Frees a held calibration: from the next solve on, every adjustment estimates it
    /// within its priors (the rig's and interior's blocks, as with
    /// [`AdjustConfig::estimate_rig`]), each slide carrying the leaving epoch's share.
    pub fn free_calibration(&mut self) {
        self.calibration_held = false;
    }

    /// Holds the calibration at its current values again (see
    /// [`AdjustConfig::hold_calibration`]).
    pub fn hold_calibration(&mut self) {
        self.calibration_held = true;
        self.rig_cov_valid = false;
    }

    /// Takes the rig and interior blocks out of the adjustment for good, keeping their
    /// values (held or estimated) and their last standard deviations: the calibration
    /// was tested long enough, and each solve saves their partial derivatives.
    pub fn drop_calibration(&mut self) {
        self.calibration_active = false;
        self.rig_cov_valid = false;
    }

    /// Whether the calibration is held at its values (tested, not estimated).
    pub fn calibration_held(&self) -> bool {
        self.calibration_held && self.calibration_active()
    }

    /// Whether the rig and interior blocks still take part (held or free).
    pub fn calibration_active(&self) -> bool {
        self.calibration_active && (self.cfg.estimate_rig || self.cfg.self_calibration.is_some())
    }

    /// Builds the undamped reduced matrix and factors it (for the covariance).
    pub(super) fn step_matrix_only(&mut self) -> Result<(), AdjustError> {
        // The matrix of an undamped step, without the step.
        let nc = self.n_cam();
        self.build(0.0);
        self.hold_blocks();
        let res = cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL)
            .map_err(|e| e.row / 6);
        res.map_err(|slot| {
            self.singular_epoch = Some(slot.min(self.n_epochs.saturating_sub(1)));
            AdjustError::Singular { epoch: slot }
        })
    }
}
