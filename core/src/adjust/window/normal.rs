//! The normal equations: camera blocks, the point index, the Schur complement point by
//! point, the constraints and priors, back-substitution and the cost.
use super::*;

impl<'a> Window<'a> {
    pub(super) fn rig_block(&self) -> Option<usize> {
        (self.cfg.estimate_rig && self.calibration_active).then_some(self.n_epochs)
    }

    /// Block of the interior orientation corrections: the last one.
    pub(super) fn interior_block(&self) -> Option<usize> {
        self.cfg
            .self_calibration
            .filter(|_| self.calibration_active)
            .map(|_| self.n_epochs + self.rig_block().is_some() as usize)
    }

    pub(super) fn n_cam(&self) -> usize {
        6 * (self.n_epochs
            + self.rig_block().is_some() as usize
            + self.interior_block().is_some() as usize)
    }

    /// The rig and interior blocks a build accumulates: none for a held calibration
    /// except in its score test, since [`Self::hold_blocks`] wipes them.
    pub(super) fn built_blocks(&self) -> (Option<usize>, Option<usize>) {
        if self.calibration_held && !self.testing_calibration {
            (None, None)
        } else {
            (self.rig_block(), self.interior_block())
        }
    }

    /// With the calibration held, takes the rig and interior blocks out of the reduced
    /// system just built (unit diagonal, no coupling, zero right-hand side): the poses
    /// are solved as with a fixed calibration and the held blocks' step is zero.
    pub(super) fn hold_blocks(&mut self) {
        if !self.calibration_held {
            return;
        }
        let nc = self.n_cam();
        let first = 6 * self.n_epochs;
        for r in first..nc {
            for c in 0..=r {
                self.reduced[r * nc + c] = 0.0;
            }
            self.reduced[r * nc + r] = 1.0;
            self.rhs[r] = 0.0;
        }
    }

    /// Scratch index of the rig's block (the epochs use their slot).
    pub(super) fn rig_scratch(&self) -> usize {
        self.cfg.window
    }

    /// Scratch index of the interior orientation's block.
    pub(super) fn interior_scratch(&self) -> usize {
        self.cfg.window + 1
    }

    /// Block of the reduced system for scratch index `sidx`.
    pub(super) fn block_of(&self, sidx: usize) -> usize {
        if sidx < self.cfg.window {
            sidx
        } else if sidx == self.rig_scratch() {
            self.rig_block().unwrap_or(0)
        } else {
            self.interior_block().unwrap_or(0)
        }
    }

    /// Projection through the cached rotations of epoch `slot` and the rig, with the
    /// `partials` the caller uses. Inlined into its callers: returned from a call, the
    /// projection and its partials (350 bytes) were copied once per observation.
    #[inline(always)]
    pub(super) fn project(
        &self,
        at: At,
        cam: Camera,
        xyz: &[f64; 3],
        partials: Partials,
    ) -> Result<crate::adjust::geometry::RigProjection, crate::camera::CameraError> {
        let (rot, c) = self.pose_parts(at);
        let f = corrected_focal(self.focal, cam, &self.interior);
        let pr = project_epoch(&rot, &c, &self.rig.base, cam, f, xyz, partials)?;
        Ok(with_interior(pr, cam, f, &self.interior))
    }

    /// Recomputes the cached rotations after the parameters changed.
    pub(super) fn refresh_rotations(&mut self) {
        let a = self.rig.angles;
        self.rig_rot = Rotations::new(a[0], a[1], a[2]);
        for e in self.epochs[..self.n_epochs].iter_mut() {
            e.rot = Rotations::with_turn(e.params[0], e.params[1], e.params[2]);
            e.right = right_rotation(&e.rot, &self.rig_rot);
        }
        for e in self.fixed[..self.n_fixed].iter_mut() {
            e.right = right_rotation(&e.rot, &self.rig_rot);
        }
    }

    /// Groups the observations by point (counting sort).
    pub(super) fn build_index(&mut self) {
        let np = self.n_point_slots;
        self.point_start[..np + 1].fill(0);
        for o in &self.obs[..self.n_obs] {
            self.point_start[o.point as usize + 1] += 1;
        }
        for p in 0..np {
            self.point_start[p + 1] += self.point_start[p];
        }
        // Fill using point_start as moving cursors, then restore.
        for i in 0..self.n_obs {
            let p = self.obs[i].point as usize;
            let at = self.point_start[p] as usize;
            self.obs_order[at] = i as u32;
            self.point_start[p] += 1;
        }
        for p in (1..=np).rev() {
            self.point_start[p] = self.point_start[p - 1];
        }
        self.point_start[0] = 0;
        self.indexed = Some(np);
    }

    /// Builds point `p`'s blocks from its observations with weight factors
    /// (`rig`/`scratch` filled for the touched camera blocks). Returns `None`
    /// when the point has no usable observation.
    pub(super) fn point_blocks(&mut self, p: usize, cams: CamBlocks) -> (PointBlocks, f64, usize) {
        self.point_blocks_with(p, cams, false)
    }

    /// [`Self::point_blocks`]; `cams` says which camera blocks to accumulate; with
    /// `all` every observation counts with factor 1.
    pub(super) fn point_blocks_with(
        &mut self,
        p: usize,
        cams: CamBlocks,
        all: bool,
    ) -> (PointBlocks, f64, usize) {
        let (want_cam, full) = (cams != CamBlocks::None, cams == CamBlocks::Full);
        let mut v = Matrix3::<f64>::zeros();
        let mut b = Vector3::<f64>::zeros();
        let mut cost = 0.0;
        let mut behind = 0;
        let mut used = 0;
        let mut touched = 0usize;
        let xyz = self.points[p].xyz;
        let (rig_block, interior_block) = self.built_blocks();
        let (s0, s1) = (
            self.point_start[p] as usize,
            self.point_start[p + 1] as usize,
        );
        for k in s0..s1 {
            let oi = self.obs_order[k] as usize;
            let mut o = self.obs[oi];
            if all {
                o.factor = 1.0;
            }
            if !(o.factor > 0.0) {
                continue;
            }
            let Some(at) = self.locate(o.epoch) else {
                continue;
            };
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            // Camera blocks need the pose's partials (a window epoch) and the rig's
            // (a right observation with the rig in the system); the point's always.
            let on_rig = cam == Camera::Right && rig_block.is_some();
            let partials = match (want_cam, at, on_rig) {
                (false, _, _) => Partials::Point,
                (true, _, true) => Partials::PoseAndRig,
                (true, At::Window(_), false) => Partials::Pose,
                (true, At::Fixed(_), false) => Partials::Point,
            };
            let pr = match self.project(at, cam, &xyz, partials) {
                Ok(pr) => pr,
                Err(_) => {
                    self.obs[oi].flags |= Observation::BEHIND;
                    behind += 1;
                    continue;
                }
            };
            self.obs[oi].flags &= !Observation::BEHIND;
            used += 1;
            let r = [o.xy[0] as f64 - pr.xy[0], o.xy[1] as f64 - pr.xy[1]];
            let f = o.factor as f64;
            let wt = [o.weight[0] as f64 * f, o.weight[1] as f64 * f];
            for c in 0..2 {
                cost += wt[c] * r[c] * r[c];
                let jp = &pr.d_point[c];
                for i in 0..3 {
                    b[i] += wt[c] * jp[i] * r[c];
                    for j in 0..3 {
                        v[(i, j)] += wt[c] * jp[i] * jp[j];
                    }
                }
            }
            if !want_cam {
                continue;
            }
            // Camera blocks touched by this observation (scratch index, Jacobian):
            // its epoch (a fixed epoch's pose is not adjusted), the rig (right
            // camera), the interior orientation; the calibration is shared by all.
            let slot = match at {
                At::Window(slot) => Some(slot),
                At::Fixed(_) => None,
            };
            if slot.is_none() && !on_rig && interior_block.is_none() {
                continue;
            }
            let blocks = [
                slot.map(|slot| (slot, &pr.d_pose)),
                on_rig.then_some((self.rig_scratch(), &pr.d_rig)),
                interior_block.map(|_| (self.interior_scratch(), &pr.d_interior)),
            ];
            for (which, blk) in blocks.iter().enumerate() {
                let Some((sidx, jc)) = *blk else { continue };
                if !self.touched[..touched].contains(&(sidx as u32)) {
                    self.touched[touched] = sidx as u32;
                    touched += 1;
                    // Only the parts this pass accumulates (the scratch is 1 KiB a block).
                    let sc = &mut self.scratch[sidx];
                    sc.w = [0.0; 18];
                    if full {
                        sc.g = [0.0; 6];
                        sc.u = [0.0; 36];
                        if rig_block.is_some() {
                            sc.u_rig = [0.0; 36];
                        }
                        if interior_block.is_some() {
                            sc.u_interior = [0.0; 36];
                        }
                    }
                }
                let sc = &mut self.scratch[sidx];
                for c in 0..2 {
                    for i in 0..6 {
                        let wi = wt[c] * jc[c][i];
                        for j in 0..3 {
                            sc.w[i * 3 + j] += wi * pr.d_point[c][j];
                        }
                        if !full {
                            continue;
                        }
                        sc.g[i] += wi * r[c];
                        // The lower triangle: all the reduced system is read for.
                        for j in 0..=i {
                            sc.u[i * 6 + j] += wi * jc[c][j];
                        }
                        // Cross blocks with the later blocks: epoch x rig, epoch x
                        // interior, rig x interior (J_this^T W J_other).
                        if which == 0 && on_rig {
                            for j in 0..6 {
                                sc.u_rig[i * 6 + j] += wi * pr.d_rig[c][j];
                            }
                        }
                        if which < 2 && interior_block.is_some() {
                            for j in 0..6 {
                                sc.u_interior[i * 6 + j] += wi * pr.d_interior[c][j];
                            }
                        }
                    }
                }
            }
        }
        let pt = &self.points[p];
        if pt.flags & PT_PRIOR != 0 {
            let wp = 1.0 / (pt.prior_sigma * pt.prior_sigma);
            for i in 0..3 {
                let r = pt.prior[i] - pt.xyz[i];
                v[(i, i)] += wp;
                b[i] += wp * r;
                cost += wp * r * r;
            }
        }
        (
            PointBlocks {
                v,
                b,
                used,
                touched,
            },
            cost,
            behind,
        )
    }

    /// Builds and solves the damped system and applies the step. Returns the cost
    /// of the state the system was built at (as [`Self::build`]) and, on a singular
    /// system, the slot of the undetermined epoch.
    pub(super) fn step(&mut self, lambda: f64) -> (f64, Result<(), usize>) {
        let cost = self.build(lambda);
        (cost, self.solve_and_apply(lambda))
    }

    /// Solves the system [`Self::build`] left and applies the step.
    fn solve_and_apply(&mut self, lambda: f64) -> Result<(), usize> {
        let nc = self.n_cam();
        let rig_block = self.rig_block();
        self.hold_blocks();
        for i in 0..nc {
            self.reduced[i * nc + i] *= 1.0 + lambda;
        }
        cholesky::factor(&mut self.reduced[..nc * nc], nc, cholesky::PIVOT_REL_TOL)
            .map_err(|e| e.row / 6)?;
        cholesky::solve(&self.reduced[..nc * nc], nc, &mut self.rhs[..nc]);
        self.back_substitute(lambda);
        for e in 0..self.n_epochs {
            let d = &self.rhs[6 * e..6 * e + 6];
            let p = &mut self.epochs[e].params;
            attitude::turn(p, [d[0], d[1], d[2]]);
            for i in 3..6 {
                p[i] += d[i];
            }
        }
        if let Some(rb) = rig_block {
            let mut r = self.rig.to_array();
            for (i, ri) in r.iter_mut().enumerate() {
                *ri += self.rhs[6 * rb + i];
            }
            self.rig = RelativeOrientation::from_array(&r);
        }
        if let Some(ib) = self.interior_block() {
            for i in 0..6 {
                self.interior[i] += self.rhs[6 * ib + i];
            }
        }
        Ok(())
    }

    /// The reduced camera system `S dc = rhs` (lower triangle, undamped
    /// camera diagonal, points damped by `lambda`) into `reduced` and `rhs`.
    ///
    /// Decides which points take part (two rays or more, not at infinity) and
    /// returns the cost (`vTPv`, constraints included) of that set at the current
    /// state: the cost an iteration sequence starts from, so that costs compare
    /// like with like. Its sum runs point by point; [`Self::cost`]'s, observation by
    /// observation, rounds differently.
    pub(super) fn build(&mut self, lambda: f64) -> f64 {
        self.refresh_rotations();
        let nc = self.n_cam();
        let (rig_block, interior_block) = self.built_blocks();
        self.reduced[..nc * nc].fill(0.0);
        self.rhs[..nc].fill(0.0);
        let mut cost = 0.0;
        for p in 0..self.n_point_slots {
            if self.points[p].flags & PT_USED == 0 {
                continue;
            }
            let (pb, point_cost, _) = self.point_blocks(p, CamBlocks::Full);
            let vinv = self.usable_point(p, &pb, lambda);
            // Excluded or not does not depend on the damping; the damped inverse
            // alone may still fail.
            if self.points[p].flags & PT_EXCLUDED == 0 {
                cost += point_cost;
            }
            let Some(vinv) = vinv else {
                continue;
            };
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let later = [
                    rig_block.filter(|_| a < self.cfg.window),
                    interior_block.filter(|_| a != self.interior_scratch()),
                ];
                let sa = &self.scratch[a];
                // U (its lower triangle), gradient, and the cross blocks with the rig
                // and the interior.
                for i in 0..6 {
                    self.rhs[6 * ba + i] += sa.g[i];
                    for j in 0..=i {
                        self.reduced[(6 * ba + i) * nc + 6 * ba + j] += sa.u[i * 6 + j];
                    }
                }
                // Row (later block) param i, column (this block) param j: the
                // transpose of J_this^T W J_other. Both later blocks follow the epochs.
                for (later, cross) in later.into_iter().zip([&sa.u_rig, &sa.u_interior]) {
                    let Some(lb) = later else { continue };
                    for i in 0..6 {
                        for j in 0..6 {
                            self.reduced[(6 * lb + i) * nc + 6 * ba + j] += cross[j * 6 + i];
                        }
                    }
                }
                // W_a V^-1 (6x3), then -W_a V^-1 W_b^T for blocks b <= a, and -W_a V^-1 b.
                let wa = nalgebra::Matrix6x3::from_row_slice(&sa.w);
                let wav = wa * vinv;
                let g = wav * pb.b;
                for i in 0..6 {
                    self.rhs[6 * ba + i] -= g[i];
                }
                for tj in 0..pb.touched {
                    let bidx = self.touched[tj] as usize;
                    let bb = self.block_of(bidx);
                    if bb > ba {
                        continue;
                    }
                    let wb = nalgebra::Matrix6x3::from_row_slice(&self.scratch[bidx].w);
                    let m = wav * wb.transpose();
                    for i in 0..6 {
                        let last = if bb == ba { i } else { 5 };
                        for j in 0..=last {
                            self.reduced[(6 * ba + i) * nc + 6 * bb + j] -= m[(i, j)];
                        }
                    }
                }
            }
        }
        cost + self.add_constraints(true).0
    }

    /// Point steps `dp = V^-1 (b_p - W^T dc)` with the camera step in `rhs`, applied.
    pub(super) fn back_substitute(&mut self, lambda: f64) {
        for p in 0..self.n_point_slots {
            if self.points[p].flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            // The point's step needs only its own blocks and the cross blocks W.
            let (pb, _, _) = self.point_blocks(p, CamBlocks::Cross);
            let Some(vinv) = self.usable_point(p, &pb, lambda) else {
                continue;
            };
            let mut rhs = pb.b;
            for ti in 0..pb.touched {
                let a = self.touched[ti] as usize;
                let ba = self.block_of(a);
                let wa = nalgebra::Matrix6x3::from_row_slice(&self.scratch[a].w);
                let dc = nalgebra::Vector6::from_column_slice(&self.rhs[6 * ba..6 * ba + 6]);
                rhs -= wa.transpose() * dc;
            }
            let dp = vinv * rhs;
            for i in 0..3 {
                self.points[p].xyz[i] += dp[i];
            }
        }
    }

    /// Damped inverse of a point's `V`, or `None` (point excluded) when it has
    /// fewer than two rays or is at infinity.
    pub(super) fn usable_point(
        &mut self,
        p: usize,
        pb: &PointBlocks,
        lambda: f64,
    ) -> Option<Matrix3<f64>> {
        let has_prior = self.points[p].flags & PT_PRIOR != 0;
        let ok_count = pb.used >= 2 || (has_prior && pb.used >= 1);
        let inv = if ok_count { sym3_inverse(&pb.v) } else { None };
        match inv {
            Some(_) => {
                self.points[p].flags &= !PT_EXCLUDED;
                let mut v = pb.v;
                for i in 0..3 {
                    v[(i, i)] *= 1.0 + lambda;
                }
                v.try_inverse()
            }
            None => {
                self.points[p].flags |= PT_EXCLUDED;
                None
            }
        }
    }

    /// A prior with full information `info` on the six parameters of camera block
    /// `block` whose residual (prior - estimate) is `r`: added to the reduced system
    /// when `normal`; returns its `vTPv`.
    pub(super) fn block_prior(
        &mut self,
        normal: bool,
        block: usize,
        r: &[f64; 6],
        info: &[f64; 36],
    ) -> f64 {
        let nc = self.n_cam();
        let mut cost = 0.0;
        for i in 0..6 {
            let mut ir = 0.0;
            for j in 0..6 {
                ir += info[i * 6 + j] * r[j];
                if normal {
                    self.reduced[(6 * block + i) * nc + 6 * block + j] += info[i * 6 + j];
                }
            }
            cost += r[i] * ir;
            if normal {
                self.rhs[6 * block + i] -= ir;
            }
        }
        cost
    }

    /// Adds the camera constraints to the reduced system (when `normal`) and
    /// returns their `vTPv` and equation count.
    pub(super) fn add_constraints(&mut self, normal: bool) -> (f64, usize) {
        let mut cost = 0.0;
        let mut count = 0;
        let s = self.cfg.sigmas;
        // Pose priors (datum, carried prior) with full information.
        for e in 0..self.n_epochs {
            let ep = self.epochs[e];
            if ep.flags & EP_PRIOR == 0 {
                continue;
            }
            let r = pose_prior_residual(&ep.params, &ep.prior);
            count += 6;
            cost += self.block_prior(normal, e, &r, &ep.prior_info);
        }
        // A held calibration is no unknown and its priors no equations: the global
        // test and its degrees of freedom are those of the fixed calibration.
        let counted = !self.calibration_held as usize;
        if let Some(rb) = self.rig_block() {
            let r = prior_residual(&self.rig.to_array(), &self.rig_prior.to_array());
            let info = self.rig_prior_info;
            cost += self.block_prior(normal, rb, &r, &info);
            count += 6 * counted;
            if s.base_length_m > 0.0 {
                let (e, g) = base_length(&self.rig.base, self.nominal_base);
                let w = 1.0 / (s.base_length_m * s.base_length_m);
                cost += self.row(
                    normal,
                    &[(6 * rb + 3, g[0]), (6 * rb + 4, g[1]), (6 * rb + 5, g[2])],
                    e,
                    w,
                );
                count += counted;
            }
        }
        if let Some(ib) = self.interior_block() {
            let r = prior_residual(&self.interior, &self.interior_prior);
            let info = self.interior_prior_info;
            cost += self.block_prior(normal, ib, &r, &info);
            count += 6 * counted;
        }
        for e in 0..self.n_epochs {
            let ep = self.epochs[e];
            let centres =
                |k: usize| -> [f64; 3] { [0, 1, 2].map(|a| self.epochs[k].params[3 + a]) };
            let (c1, c2) = (centres(e.saturating_sub(1)), centres(e));
            if ep.flags & EP_GNSS != 0 {
                let w = 1.0 / (ep.gnss_sigma * ep.gnss_sigma);
                let (r, j) = gnss_residual(&ep);
                for a in 0..3 {
                    // The centre's own column and the three angles (the other centre
                    // columns are zero).
                    let mut row = [(6 * e + 3 + a, j[a][3 + a]); 4];
                    for k in 0..3 {
                        row[k + 1] = (6 * e + k, j[a][k]);
                    }
                    cost += self.row(normal, &row, r[a], w);
                }
                count += 3;
            }
            if ep.flags & EP_ODOMETER != 0 && e > 0 {
                let (r, g) = distance(&c1, &c2, ep.odometer);
                let w = 1.0 / (ep.odometer_sigma * ep.odometer_sigma);
                let j = [
                    (6 * (e - 1) + 3, -g[0]),
                    (6 * (e - 1) + 4, -g[1]),
                    (6 * (e - 1) + 5, -g[2]),
                    (6 * e + 3, g[0]),
                    (6 * e + 4, g[1]),
                    (6 * e + 5, g[2]),
                ];
                cost += self.row(normal, &j, r, w);
                count += 1;
            }
            if s.velocity_change_mps > 0.0 {
                let (c, n) = self.add_smoothness(normal, e, s.velocity_change_mps);
                cost += c;
                count += n;
            }
        }
        (cost, count)
    }

    /// The motion smoothness ending at window slot `e`: its velocity against the
    /// velocity before it. The epochs before the window's first slot are the fixed
    /// slots, constants without a column: without them the chain broke at the
    /// window's trailing edge, and the first slot's step, tied by its marginal prior
    /// alone, jumped where the images determine the translation poorly (a straight
    /// past open ground, few and far tie points: 0.3 m errors on 2 m steps).
    pub(super) fn add_smoothness(
        &mut self,
        normal: bool,
        e: usize,
        sigma_mps: f64,
    ) -> (f64, usize) {
        let i = self.n_fixed + e;
        if i < 2 {
            return (0.0, 0);
        }
        let nodes = [
            self.motion_node(i - 2),
            self.motion_node(i - 1),
            self.motion_node(i),
        ];
        let (dt0, dt1) = (nodes[1].1 - nodes[0].1, nodes[2].1 - nodes[1].1);
        if !(dt0 > 0.0 && dt1 > 0.0) {
            return (0.0, 0);
        }
        let (r, jac) = smoothness([&nodes[0].0, &nodes[1].0, &nodes[2].0], dt0, dt1);
        let w = 1.0 / (sigma_mps * sigma_mps);
        let mut cost = 0.0;
        for (ra, ja) in r.iter().zip(&jac) {
            // Slots ascend with the nodes, as `row` wants its indices.
            let mut j = [(0, 0.0); 18];
            let mut n = 0;
            for (k, node) in nodes.iter().enumerate() {
                if let Some(slot) = node.2 {
                    for q in 0..6 {
                        j[n] = (6 * slot + q, ja[6 * k + q]);
                        n += 1;
                    }
                }
            }
            cost += self.row(normal, &j[..n], *ra, w);
        }
        (cost, 3)
    }

    /// Parameters, time and window slot (`None`: fixed) of the `i`-th epoch counted
    /// from the oldest fixed slot.
    pub(super) fn motion_node(&self, i: usize) -> ([f64; 6], f64, Option<usize>) {
        if i < self.n_fixed {
            let f = &self.fixed[i];
            (f.params, f.time, None)
        } else {
            let e = i - self.n_fixed;
            (self.epochs[e].params, self.epochs[e].time, Some(e))
        }
    }

    /// One scalar constraint `e` with sparse gradient `j` (ascending indices) and weight `w`.
    pub(super) fn row(&mut self, normal: bool, j: &[(usize, f64)], e: f64, w: f64) -> f64 {
        if normal {
            let nc = self.n_cam();
            for &(a, ca) in j {
                self.rhs[a] -= w * ca * e;
                for &(b, cb) in j {
                    if b <= a {
                        self.reduced[a * nc + b] += w * ca * cb;
                    }
                }
            }
        }
        w * e * e
    }

    /// `vTPv` at the current state, constraints included.
    pub(super) fn cost(&mut self) -> (f64, usize) {
        self.refresh_rotations();
        let mut cost = 0.0;
        let mut behind = 0;
        // Observation by observation, projections without Jacobians.
        for i in 0..self.n_obs {
            let o = self.obs[i];
            let pt = &self.points[o.point as usize];
            if !(o.factor > 0.0) || pt.flags & (PT_USED | PT_EXCLUDED) != PT_USED {
                continue;
            }
            let Some(at) = self.locate(o.epoch) else {
                continue;
            };
            let (rot, c) = self.pose_parts(at);
            let cam = if o.camera == 0 {
                Camera::Left
            } else {
                Camera::Right
            };
            let f = corrected_focal(self.focal, cam, &self.interior);
            match project_xy(rot.left, &c, &self.rig_rot, &self.rig.base, cam, f, &pt.xyz) {
                Some(xy) => {
                    let xy = shift_principal_point(xy, cam, &self.interior);
                    let r = [o.xy[0] as f64 - xy[0], o.xy[1] as f64 - xy[1]];
                    let w = o.weights();
                    cost += o.factor as f64 * (w[0] * r[0] * r[0] + w[1] * r[1] * r[1]);
                    self.obs[i].flags &= !Observation::BEHIND;
                }
                None => {
                    self.obs[i].flags |= Observation::BEHIND;
                    behind += 1;
                }
            }
        }
        for pt in &self.points[..self.n_point_slots] {
            if pt.flags & (PT_USED | PT_EXCLUDED | PT_PRIOR) == PT_USED | PT_PRIOR {
                let wp = 1.0 / (pt.prior_sigma * pt.prior_sigma);
                for a in 0..3 {
                    let r = pt.prior[a] - pt.xyz[a];
                    cost += wp * r * r;
                }
            }
        }
        (cost + self.add_constraints(false).0, behind)
    }

    pub(super) fn save(&mut self) {
        let nc = self.n_cam();
        for e in 0..self.n_epochs {
            self.saved_cam[6 * e..6 * e + 6].copy_from_slice(&self.epochs[e].params);
        }
        if let Some(rb) = self.rig_block() {
            self.saved_cam[6 * rb..6 * rb + 6].copy_from_slice(&self.rig.to_array());
        }
        if let Some(ib) = self.interior_block() {
            self.saved_cam[6 * ib..6 * ib + 6].copy_from_slice(&self.interior);
        }
        let _ = nc;
        for p in 0..self.n_point_slots {
            self.saved_points[3 * p..3 * p + 3].copy_from_slice(&self.points[p].xyz);
        }
    }

    pub(super) fn restore(&mut self) {
        for e in 0..self.n_epochs {
            self.epochs[e]
                .params
                .copy_from_slice(&self.saved_cam[6 * e..6 * e + 6]);
        }
        if let Some(rb) = self.rig_block() {
            let mut r = [0.0; 6];
            r.copy_from_slice(&self.saved_cam[6 * rb..6 * rb + 6]);
            self.rig = RelativeOrientation::from_array(&r);
        }
        if let Some(ib) = self.interior_block() {
            self.interior
                .copy_from_slice(&self.saved_cam[6 * ib..6 * ib + 6]);
        }
        for p in 0..self.n_point_slots {
            self.points[p]
                .xyz
                .copy_from_slice(&self.saved_points[3 * p..3 * p + 3]);
        }
    }
}
