//! Building the window: its construction from the arena, epochs, points, observations
//! and the GNSS, odometer and prior constraints on them.
use super::*;

impl<'a> Window<'a> {
    /// An empty window for `rig`, carving its buffers from `arena`.
    pub fn new(cfg: AdjustConfig, rig: &Rig, arena: &mut Arena<'a>) -> Result<Self, AdjustError> {
        cfg.validate()?;
        if rig.validate().is_err() || !(rig.base_length() > 1e-9) {
            return Err(AdjustError::ZeroBase);
        }
        let nc = cfg.cam_capacity();
        let (p, o, w) = (cfg.max_points, cfg.max_observations, cfg.window);
        let epochs = arena.alloc_slice::<EpochSlot>(w)?;
        let fixed = arena.alloc_slice::<FixedSlot>(cfg.fixed_epochs)?;
        let points = arena.alloc_slice::<PointSlot>(p)?;
        let obs = arena.alloc_slice::<Observation>(o)?;
        let point_start = arena.alloc_slice::<u32>(p + 1)?;
        let obs_order = arena.alloc_slice::<u32>(o)?;
        let reduced = arena.alloc_slice::<f64>(nc * nc)?;
        let rhs = arena.alloc_slice::<f64>(nc)?;
        let saved_cam = arena.alloc_slice::<f64>(nc)?;
        let saved_points = arena.alloc_slice::<f64>(3 * p)?;
        let scratch = arena.alloc_slice::<BlockScratch>(w + cfg.extra_blocks())?;
        let touched = arena.alloc_slice::<u32>(w + cfg.extra_blocks())?;
        let residuals = arena.alloc_slice::<f64>(o)?;
        let r = RelativeOrientation::from_rig(rig);
        Ok(Window {
            cfg,
            rig: r,
            rig_prior: r,
            rig_prior_info: calibration_info(&cfg.sigmas),
            nominal_base: rig.base_length(),
            focal: [rig.left.focal_mm, rig.right.focal_mm],
            rig_std: [0.0; 6],
            rig_cov: [0.0; 36],
            rig_cov_valid: false,
            cov_s02: 1.0,
            rig_rot: Rotations::new(r.angles[0], r.angles[1], r.angles[2]),
            interior: [0.0; 6],
            interior_prior: [0.0; 6],
            interior_prior_info: cfg.self_calibration.map_or([0.0; 36], |c| c.information()),
            interior_std: [0.0; 6],
            interior_cov: [0.0; 36],
            origin: [0.0; 3],
            epochs,
            n_epochs: 0,
            fixed,
            n_fixed: 0,
            first_id: 0,
            points,
            n_point_slots: 0,
            obs,
            n_obs: 0,
            point_start,
            obs_order,
            indexed: None,
            reduced,
            rhs,
            saved_cam,
            saved_points,
            scratch,
            touched,
            residuals,
            dropped_points: 0,
            dropped_observations: 0,
            singular_epoch: None,
            calibration_active: true,
            calibration_held: cfg.hold_calibration,
            testing_calibration: false,
        })
    }

    pub fn config(&self) -> &AdjustConfig {
        &self.cfg
    }

    /// Sets the nominal base length used by the base-length constraint (defaults to `|b|`).
    pub fn set_base_length(&mut self, metres: f64) {
        self.nominal_base = metres;
    }

    // ----- building the window -----

    /// Adds an epoch with the approximate pose of its left camera (object
    /// coordinates) and its time (seconds). The first epoch of an empty window
    /// carries the datum. Returns the epoch id.
    pub fn add_epoch(&mut self, left: &Pose, time_s: f64) -> Result<u32, AdjustError> {
        let params = left.to_params();
        if !params.iter().all(|v| v.is_finite()) || !time_s.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        if self.n_epochs >= self.cfg.window {
            return Err(AdjustError::WindowFull);
        }
        if self.n_epochs == 0 {
            self.origin = left.centre;
        }
        let mut local = params;
        for a in 0..3 {
            local[3 + a] -= self.origin[a];
        }
        let id = self.first_id + self.n_epochs as u32;
        let mut slot = EpochSlot::zeroed();
        slot.params = local;
        slot.time = time_s;
        slot.id = id;
        if self.n_epochs == 0 {
            slot.prior = local;
            slot.prior_info = self.cfg.sigmas.datum_information();
            slot.flags |= EP_PRIOR;
        }
        self.epochs[self.n_epochs] = slot;
        self.n_epochs += 1;
        Ok(id)
    }

    pub(super) fn slot_of(&self, epoch: u32) -> Option<usize> {
        let s = epoch.checked_sub(self.first_id)? as usize;
        (s < self.n_epochs).then_some(s)
    }

    /// The window slot or the fixed slot of an epoch id.
    pub(super) fn locate(&self, epoch: u32) -> Option<At> {
        if let Some(s) = self.slot_of(epoch) {
            return Some(At::Window(s));
        }
        let back = self.first_id.checked_sub(epoch)? as usize;
        (back >= 1 && back <= self.n_fixed).then(|| At::Fixed(self.n_fixed - back))
    }

    /// Cached rotations and local centre of the pose at `at`.
    pub(super) fn pose_parts(&self, at: At) -> (EpochRotations<'_>, [f64; 3]) {
        let (rot, right, p) = match at {
            At::Window(s) => {
                let e = &self.epochs[s];
                (&e.rot, &e.right, &e.params)
            }
            At::Fixed(s) => {
                let e = &self.fixed[s];
                (&e.rot, &e.right, &e.params)
            }
        };
        let rot = EpochRotations {
            left: rot,
            rel: &self.rig_rot,
            right,
        };
        (rot, [p[3], p[4], p[5]])
    }

    /// Local parameters of the pose at `at`.
    pub(super) fn params_at(&self, at: At) -> [f64; 6] {
        match at {
            At::Window(s) => self.epochs[s].params,
            At::Fixed(s) => self.fixed[s].params,
        }
    }

    /// A prior on an epoch's pose (object coordinates) with standard
    /// deviations (the attitude's turn about the object axes, rad; positions m);
    /// replaces any earlier prior.
    pub fn set_pose_prior(
        &mut self,
        epoch: u32,
        pose: &Pose,
        sigmas: [f64; 6],
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        let mut p = pose.to_params();
        if !p.iter().chain(sigmas.iter()).all(|v| v.is_finite()) || sigmas.iter().any(|s| *s <= 0.0)
        {
            return Err(AdjustError::NotFinite);
        }
        for a in 0..3 {
            p[3 + a] -= self.origin[a];
        }
        let e = &mut self.epochs[slot];
        e.prior = p;
        e.prior_info = [0.0; 36];
        for i in 0..6 {
            e.prior_info[i * 6 + i] = 1.0 / (sigmas[i] * sigmas[i]);
        }
        e.flags |= EP_PRIOR;
        Ok(())
    }

    /// A GNSS position of the epoch's left perspective centre with its sigma (m).
    pub fn set_gnss(
        &mut self,
        epoch: u32,
        position: [f64; 3],
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        self.set_gnss_antenna(epoch, position, sigma_m, [0.0; 3])
    }

    /// A GNSS position of an antenna at `lever_arm` from the epoch's left perspective
    /// centre (left camera frame: x right, y up, z backwards, m) with its sigma (m): the
    /// constraint `C + M^T lever_arm = G`.
    pub fn set_gnss_antenna(
        &mut self,
        epoch: u32,
        position: [f64; 3],
        sigma_m: f64,
        lever_arm: [f64; 3],
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !finite(&position) || !finite(&lever_arm) || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let e = &mut self.epochs[slot];
        e.gnss = [
            position[0] - self.origin[0],
            position[1] - self.origin[1],
            position[2] - self.origin[2],
        ];
        e.gnss_sigma = sigma_m;
        e.gnss_lever = lever_arm;
        e.flags |= EP_GNSS;
        // A fix, not the past held exact, anchors the window from now on
        // ([`Self::slide`]): the first fix after an outage pulls at once.
        self.release_fixed();
        Ok(())
    }

    /// An odometer distance (m) from the previous epoch to this one with its sigma.
    pub fn set_odometer(
        &mut self,
        epoch: u32,
        distance_m: f64,
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        let slot = self.slot_of(epoch).ok_or(AdjustError::Unknown)?;
        if !distance_m.is_finite() || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let e = &mut self.epochs[slot];
        e.odometer = distance_m;
        e.odometer_sigma = sigma_m;
        e.flags |= EP_ODOMETER;
        Ok(())
    }

    /// Adds a tie point at its approximate object coordinates; returns its index.
    pub fn add_point(&mut self, xyz: [f64; 3]) -> Result<u32, AdjustError> {
        if !xyz.iter().all(|v| v.is_finite()) {
            return Err(AdjustError::NotFinite);
        }
        let slot = match self.points[..self.n_point_slots]
            .iter()
            .position(|p| p.flags & PT_USED == 0)
        {
            Some(s) => s,
            None if self.n_point_slots < self.points.len() => {
                self.n_point_slots += 1;
                self.n_point_slots - 1
            }
            None => {
                self.dropped_points += 1;
                return Err(AdjustError::CapacityFull);
            }
        };
        let mut p = PointSlot::zeroed();
        p.xyz = [
            xyz[0] - self.origin[0],
            xyz[1] - self.origin[1],
            xyz[2] - self.origin[2],
        ];
        p.flags = PT_USED;
        p.tag = NO_TAG;
        self.points[slot] = p;
        self.indexed = None;
        Ok(slot as u32)
    }

    /// Makes a point a control point: its coordinates are observed with `sigma_m`.
    pub fn set_point_prior(
        &mut self,
        point: u32,
        xyz: [f64; 3],
        sigma_m: f64,
    ) -> Result<(), AdjustError> {
        let p = self.point_slot(point)?;
        if !xyz.iter().all(|v| v.is_finite()) || !(sigma_m > 0.0) || !sigma_m.is_finite() {
            return Err(AdjustError::NotFinite);
        }
        let o = self.origin;
        let s = &mut self.points[p];
        s.prior = [xyz[0] - o[0], xyz[1] - o[1], xyz[2] - o[2]];
        s.prior_sigma = sigma_m;
        s.flags |= PT_PRIOR;
        Ok(())
    }

    /// Tag of a live point's first observation, `None` when the point is not in use
    /// or not observed yet.
    pub fn point_tag(&self, point: u32) -> Option<u32> {
        let p = self.point_slot(point).ok()?;
        let t = self.points[p].tag;
        (t != NO_TAG).then_some(t)
    }

    pub(super) fn point_slot(&self, point: u32) -> Result<usize, AdjustError> {
        let p = point as usize;
        if p < self.n_point_slots && self.points[p].flags & PT_USED != 0 {
            Ok(p)
        } else {
            Err(AdjustError::Unknown)
        }
    }

    /// Adds an observation; returns its index.
    pub fn add_observation(&mut self, mut o: Observation) -> Result<usize, AdjustError> {
        let valid = o.xy.iter().all(|v| v.is_finite())
            && o.weight.iter().all(|w| w.is_finite() && *w > 0.0)
            && o.camera <= 1;
        if !valid {
            return Err(AdjustError::NotFinite);
        }
        self.slot_of(o.epoch).ok_or(AdjustError::Unknown)?;
        let p = self.point_slot(o.point)?;
        if self.n_obs >= self.obs.len() {
            self.dropped_observations += 1;
            return Err(AdjustError::CapacityFull);
        }
        o.factor = 1.0;
        o.flags = 0;
        self.obs[self.n_obs] = o;
        self.n_obs += 1;
        self.indexed = None;
        self.points[p].nobs += 1;
        if self.points[p].tag == NO_TAG {
            self.points[p].tag = o.tag;
        }
        Ok(self.n_obs - 1)
    }

    // ----- accessors -----
}
