//! Least squares with Levenberg-Marquardt damping, and robust weighting: Cauchy rounds,
//! data snooping and the flags they leave.
use super::*;

/// What detection found in a solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Detection {
    /// No evidence of blunders: the solution is accepted as it is.
    Passes,
    /// The global test failed (the observations' statistics were not computed).
    GlobalTestFails,
    /// An observation's statistic is past the bound: `residuals` hold the statistics
    /// of every observation of this solution, which snooping starts from.
    ObservationStandsOut,
}

impl<'a> Window<'a> {
    /// Levenberg-Marquardt to convergence with the current weight factors.
    /// Returns (iterations, converged).
    pub(super) fn least_squares(&mut self, max_iter: usize) -> Result<(usize, bool), AdjustError> {
        // The cost of the current state: the first system built gives the starting
        // state's, each accepted step's evaluation the next.
        let mut current = None;
        let mut lambda = 1e-6;
        let mut iterations = 0;
        let mut converged = false;
        while iterations < max_iter {
            iterations += 1;
            self.save();
            let (built_at, outcome) = self.step(lambda);
            let cost = *current.get_or_insert(built_at);
            match outcome {
                Ok(()) => {}
                Err(slot) => {
                    self.restore();
                    lambda *= 100.0;
                    if lambda > 1e6 {
                        self.singular_epoch = Some(slot.min(self.n_epochs.saturating_sub(1)));
                        return Err(AdjustError::Singular { epoch: slot });
                    }
                    continue;
                }
            }
            let small_step = self.step_is_small();
            let (new_cost, _) = self.cost();
            if new_cost.is_finite() && new_cost <= cost {
                let decrease = cost - new_cost;
                current = Some(new_cost);
                lambda = (lambda * 0.1).max(1e-12);
                if small_step || decrease <= self.cfg.tolerance * new_cost.max(1e-300) {
                    converged = true;
                    break;
                }
            } else {
                self.restore();
                if new_cost.is_finite() && (new_cost - cost) <= 1e-13 * cost.max(1e-300) {
                    // No representable improvement left: at the minimum.
                    converged = true;
                    break;
                }
                lambda *= 10.0;
                if lambda > 1e10 {
                    converged = true;
                    break;
                }
            }
        }
        Ok((iterations, converged))
    }

    /// Whether the last step (camera part in `rhs`) is below `step_tolerance`.
    pub(super) fn step_is_small(&self) -> bool {
        let [ta, tp] = self.cfg.step_tolerance;
        if !(ta > 0.0 && tp > 0.0) {
            return false;
        }
        self.rhs[..6 * self.n_epochs]
            .chunks_exact(6)
            .all(|d| d[..3].iter().all(|a| a.abs() <= ta) && d[3..].iter().all(|p| p.abs() <= tp))
    }

    /// Adjusts the window: least squares with the robust treatment of the
    /// configuration, then the quality figures and standard deviations.
    pub fn solve(&mut self) -> Result<Report, AdjustError> {
        if self.n_epochs == 0 {
            return Err(AdjustError::TooFewEpochs);
        }
        self.singular_epoch = None;
        self.build_index();
        let keep = self.cfg.keep_exclusions && matches!(self.cfg.robust, Robust::Snooping { .. });
        if !keep {
            for o in self.obs[..self.n_obs].iter_mut() {
                o.factor = 1.0;
                o.flags = 0;
            }
        }
        for p in self.points[..self.n_point_slots].iter_mut() {
            p.flags &= !PT_EXCLUDED;
        }
        let mut report = Report::default();
        let max_it = self.cfg.max_iterations;
        match self.cfg.robust {
            Robust::None => {
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
            }
            Robust::SeedReweight { threshold_mm } => {
                let (it, _) = self.least_squares(max_it)?;
                report.iterations += it;
                for i in 0..self.n_obs {
                    if let Some(r) = self.residual(i) {
                        if r[0].abs() > threshold_mm {
                            let o = &mut self.obs[i];
                            o.weight = [SEED_REWEIGHT as f32; 2];
                            o.flags |= Observation::FLAGGED;
                        }
                    }
                }
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
                report.robust_rounds = 1;
            }
            Robust::Snooping { critical } => {
                let (it, conv) = self.least_squares(max_it)?;
                report.iterations += it;
                report.converged = conv;
                let detection = self.detection()?;
                if detection == Detection::Passes {
                    // Accepted as is.
                } else if keep {
                    let fresh = detection == Detection::ObservationStandsOut;
                    self.snoop_rounds(critical, 1, fresh, &mut report)?;
                } else {
                    self.identify(critical, &mut report)?;
                }
            }
        }
        self.quality(&mut report)?;
        Ok(report)
    }

    /// Identification: Cauchy re-weighting, then data snooping until stable.
    pub(super) fn identify(
        &mut self,
        critical: f64,
        report: &mut Report,
    ) -> Result<(), AdjustError> {
        let max_it = self.cfg.max_iterations;
        // Cauchy re-weighting on a median scale: blunders lose their pull.
        for _ in 0..self.cfg.max_robust_rounds {
            let (it, _) = self.least_squares(max_it.min(10))?;
            report.iterations += it;
            let change = self.cauchy_factors();
            report.robust_rounds += 1;
            if change < 0.01 {
                break;
            }
        }
        // Data snooping with full weights until the excluded set is stable.
        for o in self.obs[..self.n_obs].iter_mut() {
            o.factor = 1.0;
        }
        self.snoop_rounds(critical, 0, false, report)
    }

    /// Snooping from the current solution until the excluded set is stable, then
    /// a final solution for that set. `first_round` 1 skips the hysteresis-free start;
    /// `fresh`: `residuals` already hold the statistics of the current solution
    /// ([`Detection::ObservationStandsOut`]), which the first round reads instead of
    /// computing them again (a pass over every point and observation: on the hand-held
    /// walk 0.26 G instructions of 34.9).
    pub(super) fn snoop_rounds(
        &mut self,
        critical: f64,
        first_round: usize,
        fresh: bool,
        report: &mut Report,
    ) -> Result<(), AdjustError> {
        let max_it = self.cfg.max_iterations;
        if fresh {
            self.flag_by_statistics(critical, first_round);
        } else {
            self.snoop(critical, first_round);
        }
        let mut stable = false;
        for round in first_round + 1..=first_round + self.cfg.max_robust_rounds {
            let (it, conv) = self.least_squares(max_it)?;
            report.iterations += it;
            report.converged = conv;
            report.robust_rounds += 1;
            if !self.snoop(critical, round) {
                stable = true;
                break;
            }
        }
        if !stable {
            // Out of rounds: the solution must match the final set.
            let (it, conv) = self.least_squares(max_it)?;
            report.iterations += it;
            report.converged = conv;
        }
        Ok(())
    }

    /// Standardised 2-D residual `sqrt(v^T P v)` of every observation into `residuals`.
    pub(super) fn normalised_residuals(&mut self) {
        for i in 0..self.n_obs {
            let w = self.obs[i].weights();
            self.residuals[i] = match self.residual(i) {
                Some(r) => libm::sqrt(w[0] * r[0] * r[0] + w[1] * r[1] * r[1]),
                None => f64::INFINITY,
            };
        }
    }

    /// Sets Cauchy factors from the residuals; returns the largest factor change.
    pub(super) fn cauchy_factors(&mut self) -> f64 {
        self.normalised_residuals();
        let n = self.n_obs;
        // Median of t^2 over chi2_2's median: the robust variance factor.
        let res = &*self.residuals;
        let scale2 = (median_by_rank(n, |i| Some(res[i] * res[i])) / CHI2_2_MEDIAN).max(1e-30);
        let scale = libm::sqrt(scale2);
        let mut change: f64 = 0.0;
        for i in 0..n {
            let f = cauchy_factor(self.residuals[i] / scale, 2.385);
            change = change.max((f - self.obs[i].factor as f64).abs());
            self.obs[i].factor = f as f32;
        }
        change
    }

    /// Tests every observation with `T = v^T Q_vv^-1 v`, `Q_vv = P^-1 -+ J_p V^-1 J_p^T`
    /// (point part of the cofactor: the cameras are determined by many points),
    /// on the median scale; excludes those beyond `critical`. Returns whether
    /// the excluded set changed.
    pub(super) fn snoop(&mut self, critical: f64, round: usize) -> bool {
        self.statistics();
        self.flag_by_statistics(critical, round)
    }

    /// [`Self::snoop`] on the statistics already in `residuals`.
    fn flag_by_statistics(&mut self, critical: f64, round: usize) -> bool {
        let scale2 = self.median_scale();
        self.apply_flags(critical, round, scale2)
    }

    /// Median of the accepted observations' `T` (in `residuals`) over chi2_2's median
    /// (at least [`MIN_SNOOPING_SCALE`]):
    /// 1 when the weights match the noise, and right also with the seed's weights
    /// whose scale is arbitrary. Selected in place (no copy of the residuals).
    pub(super) fn median_scale(&self) -> f64 {
        let (res, obs) = (&*self.residuals, &*self.obs);
        let used = |i: usize| (obs[i].factor > 0.0 && res[i].is_finite()).then_some(res[i]);
        (median_by_rank(self.n_obs, used) / CHI2_2_MEDIAN).max(MIN_SNOOPING_SCALE)
    }

    /// Detection (Baarda's DIA order): after plain least squares, the data are
    /// accepted without any exclusion when the global test passes and the
    /// largest `T` stays below the Bonferroni bound `-2 ln(0.05 / n)` (5 % for
    /// the whole set); otherwise the robust identification runs.
    pub(super) fn detection(&mut self) -> Result<Detection, AdjustError> {
        let mut r = Report::default();
        self.global_test(&mut r)?;
        // Only the upper tail is evidence of blunders; a sigma0 below its bound says
        // the a-priori sigma was pessimistic, and identification would be wasted work.
        if r.chi2.statistic > r.chi2.upper {
            return Ok(Detection::GlobalTestFails);
        }
        self.statistics();
        let scale2 = self.median_scale();
        let n = self.n_obs.max(1) as f64;
        let bound = -2.0 * libm::log(0.05 / n);
        let worst = self.residuals[..self.n_obs]
            .iter()
            .enumerate()
            .filter(|(i, _)| self.obs[*i].factor > 0.0)
            .fold(0.0f64, |m, (_, t)| m.max(*t));
        // On the median scale, as snooping: a pessimistic a-priori sigma must not
        // hide blunders that stand out of the actual noise.
        Ok(if worst <= bound * scale2 {
            Detection::Passes
        } else {
            Detection::ObservationStandsOut
        })
    }

    /// `T` of every observation into `residuals` (a-priori scale).
    pub(super) fn statistics(&mut self) {
        self.refresh_rotations();
        for p in 0..self.n_point_slots {
            if self.points[p].flags & PT_USED == 0 {
                continue;
            }
            let (pb, _, _) = self.point_blocks(p, CamBlocks::None);
            let mut vinv = if pb.used >= 2 {
                sym3_inverse(&pb.v)
            } else {
                None
            };
            // A point left with fewer than two rays is re-tested as if all
            // its observations were in, so a wrongly excluded point can return.
            let all = vinv.is_none();
            if all {
                let (pb, _, _) = self.point_blocks_with(p, CamBlocks::None, true);
                vinv = if pb.used >= 2 {
                    sym3_inverse(&pb.v)
                } else {
                    None
                };
            }
            let (s0, s1) = (
                self.point_start[p] as usize,
                self.point_start[p + 1] as usize,
            );
            for k in s0..s1 {
                let oi = self.obs_order[k] as usize;
                self.residuals[oi] = self.statistic(oi, vinv.as_ref(), all);
            }
        }
    }

    /// Excludes/readmits observations from their `T` on the scale `scale2`;
    /// returns whether the excluded set changed.
    pub(super) fn apply_flags(&mut self, critical: f64, round: usize, scale2: f64) -> bool {
        let n = self.n_obs;
        let mut changed = false;
        for i in 0..n {
            let t = self.residuals[i] / scale2;
            let was = self.obs[i].factor == 0.0;
            // Hysteresis from the third round: an excluded observation returns
            // only well inside the acceptance region, so the set cannot oscillate.
            let readmit = if round >= 3 { 0.5 * critical } else { critical };
            let out = if was {
                !(t <= readmit)
            } else {
                !(t <= critical)
            };
            if out != was {
                changed = true;
            }
            self.obs[i].factor = if out { 0.0 } else { 1.0 };
            if out {
                self.obs[i].flags |= Observation::FLAGGED;
            } else {
                self.obs[i].flags &= !Observation::FLAGGED;
            }
        }
        changed
    }
}
