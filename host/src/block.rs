//! Block files for `phototraverse adjust` (format: docs/block-format.md).
//!
//! A block is a directory of whitespace-separated text files, `#` starts a
//! comment: `block.txt` (cameras, rig, settings), `images.txt` (approximate
//! exterior orientation of the left camera per epoch), `observations.txt`
//! (tie points in pixels), and the optional `control.txt`, `gnss.txt`,
//! `odometer.txt`. Every parse error names the file and the line.

use anyhow::{anyhow, Context, Result};
use phototraverse_core::adjust::geometry::camera_pose;
use phototraverse_core::adjust::weighting::{weights, Scheme};
use phototraverse_core::adjust::{
    intersect, right_camera_covariance, standard_deviations, AdjustConfig, ConstraintSigmas,
    Observation, Ray, Report, Robust, Window,
};
use phototraverse_core::budget::{Arena, MemoryBudget};
use phototraverse_core::camera::{Camera, RelativeOrientation};
use phototraverse_core::camera::{DistortionModel, Interior, Pose, Rig};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

/// Observation weighting of a block (seed 000's schemes or the measuring precision).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weighting {
    Sigma,
    Parallax,
    Radial,
    Equal,
}

/// Blunder treatment of a block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobustKind {
    Snooping,
    None,
    Seed,
}

/// Settings of `block.txt`.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub sigma_px: f64,
    pub weighting: Weighting,
    pub robust: RobustKind,
    pub estimate_rig: bool,
    /// Datum sigmas: degrees, metres.
    pub datum_sigma: (f64, f64),
    /// Rig prior sigmas: degrees, metres.
    pub rig_sigma: (f64, f64),
    /// Base length constraint: value and sigma, metres.
    pub base_length: Option<(f64, f64)>,
    /// Motion smoothness sigma, m/s.
    pub velocity_sigma: Option<f64>,
    pub max_iterations: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            sigma_px: 0.3,
            weighting: Weighting::Sigma,
            robust: RobustKind::Snooping,
            estimate_rig: false,
            datum_sigma: (1e-4, 1e-4),
            rig_sigma: (0.05, 0.001),
            base_length: None,
            velocity_sigma: None,
            max_iterations: 50,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Image {
    pub epoch: u32,
    pub time_s: f64,
    pub pose: Pose,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelObservation {
    /// Line in observations.txt (1-based).
    pub line: usize,
    pub point: u64,
    pub epoch: u32,
    pub camera: Camera,
    /// Column, row (pixel centres at integers).
    pub px: [f64; 2],
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlPoint {
    pub point: u64,
    pub xyz: [f64; 3],
    pub sigma_m: f64,
}

/// A block read from files.
#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    pub rig: Rig,
    pub settings: Settings,
    pub images: Vec<Image>,
    pub observations: Vec<PixelObservation>,
    pub control: Vec<ControlPoint>,
    /// (epoch, position, sigma m)
    pub gnss: Vec<(u32, [f64; 3], f64)>,
    /// (epoch, distance from the previous epoch, sigma m)
    pub odometer: Vec<(u32, f64, f64)>,
}

/// Lines of a file without comments and blanks: (1-based line number, fields).
fn lines(path: &Path) -> Result<Vec<(usize, Vec<String>)>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(text
        .lines()
        .enumerate()
        .filter_map(|(i, l)| {
            let body = l.split('#').next().unwrap_or("").trim();
            (!body.is_empty())
                .then(|| (i + 1, body.split_whitespace().map(str::to_string).collect()))
        })
        .collect())
}

/// Error at `file:line`.
fn at(path: &Path, line: usize, msg: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("{}:{}: {}", path.display(), line, msg)
}

fn nums<const N: usize>(path: &Path, line: usize, f: &[String], what: &str) -> Result<[f64; N]> {
    if f.len() != N {
        return Err(at(
            path,
            line,
            format!("{what}: expected {N} numbers, found {}", f.len()),
        ));
    }
    let mut out = [0.0; N];
    for (o, s) in out.iter_mut().zip(f) {
        *o = s
            .parse::<f64>()
            .map_err(|_| at(path, line, format!("{what}: `{s}` is not a number")))?;
        if !o.is_finite() {
            return Err(at(path, line, format!("{what}: `{s}` is not finite")));
        }
    }
    Ok(out)
}

fn int<T: std::str::FromStr>(path: &Path, line: usize, s: &str, what: &str) -> Result<T> {
    s.parse::<T>().map_err(|_| {
        at(
            path,
            line,
            format!("{what}: `{s}` is not a non-negative integer"),
        )
    })
}

impl Block {
    /// Reads a block directory.
    pub fn read(dir: &Path) -> Result<Block> {
        let bpath = dir.join("block.txt");
        let mut left = None;
        let mut right = None;
        let mut rel = [0.0; 3];
        let mut base = None;
        let mut s = Settings::default();
        for (ln, f) in lines(&bpath)? {
            let key = f[0].as_str();
            let rest = &f[1..];
            match key {
                "camera" => {
                    if rest.is_empty() {
                        return Err(at(
                            &bpath,
                            ln,
                            "camera: expected `left` or `right` and 11 values",
                        ));
                    }
                    let v: [f64; 11] = nums(&bpath, ln, &rest[1..], "camera")?;
                    let cam = Interior {
                        width_px: v[0] as u32,
                        height_px: v[1] as u32,
                        pixel_size_mm: [v[2], v[3]],
                        focal_mm: v[4],
                        principal_point_mm: [v[5], v[6]],
                        radial: [v[7], v[8], 0.0],
                        decentering: [v[9], v[10]],
                        distortion_model: DistortionModel::Correction,
                    };
                    cam.validate()
                        .map_err(|e| at(&bpath, ln, format!("camera: {e}")))?;
                    match rest[0].as_str() {
                        "left" => left = Some(cam),
                        "right" => right = Some(cam),
                        other => {
                            return Err(at(
                                &bpath,
                                ln,
                                format!("camera: `{other}` is not left or right"),
                            ))
                        }
                    }
                }
                "relative_deg" => rel = nums(&bpath, ln, rest, "relative_deg")?,
                "base_m" => base = Some(nums::<3>(&bpath, ln, rest, "base_m")?),
                "sigma_px" => {
                    s.sigma_px = nums::<1>(&bpath, ln, rest, "sigma_px")?[0];
                    if s.sigma_px <= 0.0 {
                        return Err(at(&bpath, ln, "sigma_px must be positive"));
                    }
                }
                "weighting" => {
                    s.weighting = match rest.first().map(String::as_str) {
                        Some("sigma") => Weighting::Sigma,
                        Some("parallax") => Weighting::Parallax,
                        Some("radial") => Weighting::Radial,
                        Some("equal") => Weighting::Equal,
                        _ => {
                            return Err(at(
                                &bpath,
                                ln,
                                "weighting: expected sigma, parallax, radial or equal",
                            ))
                        }
                    }
                }
                "robust" => {
                    s.robust = match rest.first().map(String::as_str) {
                        Some("snooping") => RobustKind::Snooping,
                        Some("none") => RobustKind::None,
                        Some("seed") => RobustKind::Seed,
                        _ => return Err(at(&bpath, ln, "robust: expected snooping, none or seed")),
                    }
                }
                "estimate_rig" => {
                    s.estimate_rig = match rest.first().map(String::as_str) {
                        Some("yes") => true,
                        Some("no") => false,
                        _ => return Err(at(&bpath, ln, "estimate_rig: expected yes or no")),
                    }
                }
                "datum_sigma" => {
                    let v: [f64; 2] = nums(&bpath, ln, rest, "datum_sigma")?;
                    if v[0] <= 0.0 || v[1] <= 0.0 {
                        return Err(at(&bpath, ln, "datum_sigma must be positive"));
                    }
                    s.datum_sigma = (v[0], v[1]);
                }
                "rig_sigma" => {
                    let v: [f64; 2] = nums(&bpath, ln, rest, "rig_sigma")?;
                    if v[0] <= 0.0 || v[1] <= 0.0 {
                        return Err(at(&bpath, ln, "rig_sigma must be positive"));
                    }
                    s.rig_sigma = (v[0], v[1]);
                }
                "base_length" => {
                    let v: [f64; 2] = nums(&bpath, ln, rest, "base_length")?;
                    if v[1] <= 0.0 {
                        return Err(at(&bpath, ln, "base_length sigma must be positive"));
                    }
                    s.base_length = Some((v[0], v[1]));
                }
                "velocity_sigma" => {
                    let v: [f64; 1] = nums(&bpath, ln, rest, "velocity_sigma")?;
                    if v[0] <= 0.0 {
                        return Err(at(&bpath, ln, "velocity_sigma must be positive"));
                    }
                    s.velocity_sigma = Some(v[0]);
                }
                "max_iterations" => {
                    s.max_iterations = int(
                        &bpath,
                        ln,
                        rest.first().map(String::as_str).unwrap_or(""),
                        "max_iterations",
                    )?;
                    if s.max_iterations == 0 {
                        return Err(at(&bpath, ln, "max_iterations must be at least 1"));
                    }
                }
                other => return Err(at(&bpath, ln, format!("unknown keyword `{other}`"))),
            }
        }
        let left = left.ok_or_else(|| at(&bpath, 0, "missing `camera left`"))?;
        let right = right.unwrap_or(left);
        let base = base.ok_or_else(|| at(&bpath, 0, "missing `base_m`"))?;
        let rig = Rig {
            left,
            right,
            relative_angles: [
                rel[0].to_radians(),
                rel[1].to_radians(),
                rel[2].to_radians(),
            ],
            base_m: base,
        };
        if rig.base_length() <= 0.0 {
            return Err(at(&bpath, 0, "the base must not be zero"));
        }

        let ipath = dir.join("images.txt");
        let mut images = Vec::new();
        for (ln, f) in lines(&ipath)? {
            if f.len() != 8 {
                return Err(at(
                    &ipath,
                    ln,
                    format!(
                        "expected `epoch time omega phi kappa X Y Z` (8 fields), found {}",
                        f.len()
                    ),
                ));
            }
            let epoch: u32 = int(&ipath, ln, &f[0], "epoch")?;
            if epoch as usize != images.len() {
                return Err(at(
                    &ipath,
                    ln,
                    format!(
                        "epochs must be 0, 1, 2, ... in order; expected {}",
                        images.len()
                    ),
                ));
            }
            let v: [f64; 7] = nums(&ipath, ln, &f[1..], "image")?;
            images.push(Image {
                epoch,
                time_s: v[0],
                pose: Pose::from_degrees(v[1], v[2], v[3], [v[4], v[5], v[6]]),
            });
        }
        if images.is_empty() {
            return Err(at(&ipath, 0, "no images"));
        }

        let opath = dir.join("observations.txt");
        let mut observations = Vec::new();
        for (ln, f) in lines(&opath)? {
            if f.len() != 5 {
                return Err(at(
                    &opath,
                    ln,
                    format!(
                        "expected `point epoch L|R column row` (5 fields), found {}",
                        f.len()
                    ),
                ));
            }
            let point: u64 = int(&opath, ln, &f[0], "point")?;
            let epoch: u32 = int(&opath, ln, &f[1], "epoch")?;
            if epoch as usize >= images.len() {
                return Err(at(
                    &opath,
                    ln,
                    format!("epoch {epoch} is not in images.txt"),
                ));
            }
            let camera = match f[2].as_str() {
                "L" | "l" => Camera::Left,
                "R" | "r" => Camera::Right,
                other => return Err(at(&opath, ln, format!("camera `{other}` is not L or R"))),
            };
            let px: [f64; 2] = nums(&opath, ln, &f[3..], "pixel")?;
            observations.push(PixelObservation {
                line: ln,
                point,
                epoch,
                camera,
                px,
            });
        }

        let mut control = Vec::new();
        let cpath = dir.join("control.txt");
        if cpath.exists() {
            for (ln, f) in lines(&cpath)? {
                if f.len() != 5 {
                    return Err(at(&cpath, ln, "expected `point X Y Z sigma_m`"));
                }
                let point: u64 = int(&cpath, ln, &f[0], "point")?;
                let v: [f64; 4] = nums(&cpath, ln, &f[1..], "control point")?;
                if v[3] <= 0.0 {
                    return Err(at(&cpath, ln, "sigma must be positive"));
                }
                control.push(ControlPoint {
                    point,
                    xyz: [v[0], v[1], v[2]],
                    sigma_m: v[3],
                });
            }
        }
        let mut gnss = Vec::new();
        let gpath = dir.join("gnss.txt");
        if gpath.exists() {
            for (ln, f) in lines(&gpath)? {
                if f.len() != 5 {
                    return Err(at(&gpath, ln, "expected `epoch X Y Z sigma_m`"));
                }
                let e: u32 = int(&gpath, ln, &f[0], "epoch")?;
                let v: [f64; 4] = nums(&gpath, ln, &f[1..], "gnss")?;
                if e as usize >= images.len() || v[3] <= 0.0 {
                    return Err(at(&gpath, ln, "unknown epoch or non-positive sigma"));
                }
                gnss.push((e, [v[0], v[1], v[2]], v[3]));
            }
        }
        let mut odometer = Vec::new();
        let dpath = dir.join("odometer.txt");
        if dpath.exists() {
            for (ln, f) in lines(&dpath)? {
                if f.len() != 3 {
                    return Err(at(&dpath, ln, "expected `epoch distance_m sigma_m`"));
                }
                let e: u32 = int(&dpath, ln, &f[0], "epoch")?;
                let v: [f64; 2] = nums(&dpath, ln, &f[1..], "odometer")?;
                if e == 0 || e as usize >= images.len() || v[1] <= 0.0 {
                    return Err(at(
                        &dpath,
                        ln,
                        "epoch must be 1.. in images.txt and sigma positive",
                    ));
                }
                odometer.push((e, v[0], v[1]));
            }
        }
        Ok(Block {
            rig,
            settings: s,
            images,
            observations,
            control,
            gnss,
            odometer,
        })
    }

    /// Writes the block's files into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir)?;
        let mut b = String::from("# phototraverse block (docs/block-format.md)\n");
        for (name, c) in [("left", &self.rig.left), ("right", &self.rig.right)] {
            writeln!(
                b,
                "camera {name} {} {} {} {} {} {} {} {:e} {:e} {:e} {:e}",
                c.width_px,
                c.height_px,
                c.pixel_size_mm[0],
                c.pixel_size_mm[1],
                c.focal_mm,
                c.principal_point_mm[0],
                c.principal_point_mm[1],
                c.radial[0],
                c.radial[1],
                c.decentering[0],
                c.decentering[1]
            )?;
        }
        let r = self.rig.relative_angles;
        writeln!(
            b,
            "relative_deg {} {} {}",
            r[0].to_degrees(),
            r[1].to_degrees(),
            r[2].to_degrees()
        )?;
        writeln!(
            b,
            "base_m {} {} {}",
            self.rig.base_m[0], self.rig.base_m[1], self.rig.base_m[2]
        )?;
        let s = &self.settings;
        writeln!(b, "sigma_px {}", s.sigma_px)?;
        let w = match s.weighting {
            Weighting::Sigma => "sigma",
            Weighting::Parallax => "parallax",
            Weighting::Radial => "radial",
            Weighting::Equal => "equal",
        };
        writeln!(b, "weighting {w}")?;
        let rb = match s.robust {
            RobustKind::Snooping => "snooping",
            RobustKind::None => "none",
            RobustKind::Seed => "seed",
        };
        writeln!(b, "robust {rb}")?;
        writeln!(
            b,
            "estimate_rig {}",
            if s.estimate_rig { "yes" } else { "no" }
        )?;
        writeln!(b, "datum_sigma {} {}", s.datum_sigma.0, s.datum_sigma.1)?;
        writeln!(b, "rig_sigma {} {}", s.rig_sigma.0, s.rig_sigma.1)?;
        if let Some((v, sg)) = s.base_length {
            writeln!(b, "base_length {v} {sg}")?;
        }
        if let Some(v) = s.velocity_sigma {
            writeln!(b, "velocity_sigma {v}")?;
        }
        writeln!(b, "max_iterations {}", s.max_iterations)?;
        std::fs::write(dir.join("block.txt"), b)?;

        let mut t = String::from(
            "# epoch time_s omega_deg phi_deg kappa_deg X_m Y_m Z_m  (left camera, approximate)\n",
        );
        for im in &self.images {
            let p = &im.pose;
            writeln!(
                t,
                "{} {:.3} {:.6} {:.6} {:.6} {:.4} {:.4} {:.4}",
                im.epoch,
                im.time_s,
                p.omega.to_degrees(),
                p.phi.to_degrees(),
                p.kappa.to_degrees(),
                p.centre[0],
                p.centre[1],
                p.centre[2]
            )?;
        }
        std::fs::write(dir.join("images.txt"), t)?;
        let mut o = String::from("# point epoch camera(L|R) column row  (pixels, (0,0) = centre of the top-left pixel)\n");
        for ob in &self.observations {
            let c = camera_code(ob.camera);
            writeln!(
                o,
                "{} {} {c} {:.3} {:.3}",
                ob.point, ob.epoch, ob.px[0], ob.px[1]
            )?;
        }
        std::fs::write(dir.join("observations.txt"), o)?;
        if !self.control.is_empty() {
            let mut c = String::from("# point X_m Y_m Z_m sigma_m\n");
            for cp in &self.control {
                writeln!(
                    c,
                    "{} {:.4} {:.4} {:.4} {}",
                    cp.point, cp.xyz[0], cp.xyz[1], cp.xyz[2], cp.sigma_m
                )?;
            }
            std::fs::write(dir.join("control.txt"), c)?;
        }
        if !self.gnss.is_empty() {
            let mut g = String::from("# epoch X_m Y_m Z_m sigma_m\n");
            for (e, x, sg) in &self.gnss {
                writeln!(g, "{e} {:.4} {:.4} {:.4} {sg}", x[0], x[1], x[2])?;
            }
            std::fs::write(dir.join("gnss.txt"), g)?;
        }
        if !self.odometer.is_empty() {
            let mut d = String::from("# epoch distance_from_previous_m sigma_m\n");
            for (e, x, sg) in &self.odometer {
                writeln!(d, "{e} {x:.4} {sg}")?;
            }
            std::fs::write(dir.join("odometer.txt"), d)?;
        }
        Ok(())
    }
}

/// One adjusted camera of one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjustedImage {
    pub epoch: u32,
    pub camera: Camera,
    pub pose: Pose,
    /// omega, phi, kappa (rad), X, Y, Z (m).
    pub std: [f64; 6],
}

/// One adjusted tie point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjustedPoint {
    pub point: u64,
    pub xyz: [f64; 3],
    pub std: [f64; 3],
    pub observations: usize,
}

/// A flagged observation with its residual in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flagged {
    pub obs: PixelObservation,
    pub residual_px: [f64; 2],
}

/// Result of a block adjustment.
#[derive(Debug, Clone)]
pub struct Adjusted {
    pub report: Report,
    pub images: Vec<AdjustedImage>,
    pub points: Vec<AdjustedPoint>,
    /// Points left out (no intersection, too few rays, at infinity).
    pub skipped_points: Vec<u64>,
    pub flagged: Vec<Flagged>,
    pub rig: RelativeOrientation,
    pub rig_std: [f64; 6],
    pub budget_bytes: usize,
}

/// Corrected photo-coordinates (mm) of a pixel observation.
fn corrected(rig: &Rig, o: &PixelObservation) -> [f64; 2] {
    rig.interior(o.camera).pixel_to_corrected(o.px[0], o.px[1])
}

/// The block's points in first-seen order, each with the indices of its observations.
struct PointObservations {
    order: Vec<u64>,
    by_point: HashMap<u64, Vec<usize>>,
}

impl PointObservations {
    fn from_block(block: &Block) -> Self {
        let mut order: Vec<u64> = Vec::new();
        let mut by_point: HashMap<u64, Vec<usize>> = HashMap::new();
        for (i, o) in block.observations.iter().enumerate() {
            by_point
                .entry(o.point)
                .or_insert_with(|| {
                    order.push(o.point);
                    Vec::new()
                })
                .push(i);
        }
        PointObservations { order, by_point }
    }
}

/// Adjusts a block with the core's window (one window holding every epoch).
pub fn adjust(block: &Block) -> Result<Adjusted> {
    let points = PointObservations::from_block(block);
    let cfg = window_config(block, &points);
    let mut budget = MemoryBudget::new();
    cfg.budget(&mut budget);
    let mut mem = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut mem);
    let mut w = Window::new(cfg, &block.rig, &mut arena).map_err(|e| anyhow!("adjustment: {e}"))?;
    add_epochs(&mut w, block)?;
    let (index, mut skipped) = add_points(&mut w, block, &points)?;
    add_observations(&mut w, block, &index)?;
    let report = w.solve().map_err(|e| match e {
        phototraverse_core::adjust::AdjustError::Singular { epoch } => {
            anyhow!("adjustment failed: {e} (epoch {epoch} of images.txt is not determined by its points)")
        }
        _ => anyhow!("adjustment failed: {e}"),
    })?;
    let images = adjusted_images(&w, block.images.len());
    let mut adjusted_points = Vec::new();
    for pid in &points.order {
        let Some(&id) = index.get(pid) else { continue };
        match (w.point(id), w.point_std(id)) {
            (Some(xyz), Some(std)) => adjusted_points.push(AdjustedPoint {
                point: *pid,
                xyz,
                std,
                observations: points.by_point[pid].len(),
            }),
            _ => skipped.push(*pid),
        }
    }
    Ok(Adjusted {
        report,
        images,
        points: adjusted_points,
        skipped_points: skipped,
        flagged: flagged(&w, block),
        rig: w.rig(),
        rig_std: w.rig_std(),
        budget_bytes: budget.total_with_prefix("adjust."),
    })
}

/// The window for the whole block: every epoch, point and observation, the settings'
/// robust estimator and constraints.
fn window_config(block: &Block, points: &PointObservations) -> AdjustConfig {
    let s = &block.settings;
    let robust = match s.robust {
        RobustKind::Snooping => Robust::snooping(),
        RobustKind::None => Robust::None,
        RobustKind::Seed => Robust::SeedReweight {
            threshold_mm: block.rig.left.pixel_size_mm[0],
        },
    };
    AdjustConfig {
        window: block.images.len(),
        max_points: points.order.len().max(1),
        max_observations: block.observations.len().max(1),
        max_iterations: s.max_iterations,
        estimate_rig: s.estimate_rig,
        sigmas: ConstraintSigmas {
            datum_angle_rad: s.datum_sigma.0.to_radians(),
            datum_position_m: s.datum_sigma.1,
            rig_angle_rad: s.rig_sigma.0.to_radians(),
            rig_base_m: s.rig_sigma.1,
            base_length_m: s.base_length.map(|b| b.1).unwrap_or(0.0),
            velocity_change_mps: s.velocity_sigma.unwrap_or(0.0),
        },
        robust,
        ..AdjustConfig::default()
    }
}

/// The epochs with their start poses, and the GNSS and odometer observations.
fn add_epochs(w: &mut Window, block: &Block) -> Result<()> {
    if let Some((b, _)) = block.settings.base_length {
        w.set_base_length(b);
    }
    for im in &block.images {
        w.add_epoch(&im.pose, im.time_s)
            .map_err(|e| anyhow!("epoch {}: {e}", im.epoch))?;
    }
    for (e, x, sg) in &block.gnss {
        w.set_gnss(*e, *x, *sg)
            .map_err(|er| anyhow!("gnss epoch {e}: {er}"))?;
    }
    for (e, d, sg) in &block.odometer {
        w.set_odometer(*e, *d, *sg)
            .map_err(|er| anyhow!("odometer epoch {e}: {er}"))?;
    }
    Ok(())
}

/// The points: control points at their coordinates with their prior, tie points at
/// the intersection of their rays from the start poses. Returns the window's id of
/// each point and the points that did not intersect.
fn add_points(
    w: &mut Window,
    block: &Block,
    points: &PointObservations,
) -> Result<(HashMap<u64, u32>, Vec<u64>)> {
    let control: BTreeMap<u64, ControlPoint> =
        block.control.iter().map(|c| (c.point, *c)).collect();
    let rp = RelativeOrientation::from_rig(&block.rig);
    let mut index: HashMap<u64, u32> = HashMap::new();
    let mut skipped = Vec::new();
    for pid in &points.order {
        let start = match control.get(pid) {
            Some(c) => Some(c.xyz),
            None => {
                let rays: Vec<Ray> = points.by_point[pid]
                    .iter()
                    .map(|&i| {
                        let o = &block.observations[i];
                        let left = block.images[o.epoch as usize].pose;
                        Ray {
                            pose: camera_pose(&left, &rp, o.camera),
                            focal_mm: block.rig.interior(o.camera).focal_mm,
                            xy: corrected(&block.rig, o),
                        }
                    })
                    .collect();
                intersect(&rays, 1e-4).ok().map(|i| i.point)
            }
        };
        let Some(xyz) = start else {
            skipped.push(*pid);
            continue;
        };
        let id = w.add_point(xyz).map_err(|e| anyhow!("point {pid}: {e}"))?;
        if let Some(c) = control.get(pid) {
            w.set_point_prior(id, c.xyz, c.sigma_m)
                .map_err(|e| anyhow!("control point {pid}: {e}"))?;
        }
        index.insert(*pid, id);
    }
    Ok((index, skipped))
}

/// The image observations of the points in the window, weighted as the settings say;
/// each keeps its index in the block as its tag.
fn add_observations(w: &mut Window, block: &Block, index: &HashMap<u64, u32>) -> Result<()> {
    // The parallax scheme needs the stereo partner.
    let mut partner: HashMap<(u64, u32, u8), [f64; 2]> = HashMap::new();
    for o in &block.observations {
        partner.insert((o.point, o.epoch, o.camera as u8), corrected(&block.rig, o));
    }
    for (i, o) in block.observations.iter().enumerate() {
        let Some(&pid) = index.get(&o.point) else {
            continue;
        };
        let xy = corrected(&block.rig, o);
        let other = partner
            .get(&(o.point, o.epoch, 1 - o.camera as u8))
            .copied();
        let wt = observation_weight(block, o, xy, other);
        let wt = [wt[0].max(1e-12), wt[1].max(1e-12)];
        let mut ob = Observation::new(o.epoch, o.camera, pid, xy, wt);
        ob.tag = i as u32;
        w.add_observation(ob)
            .map_err(|e| anyhow!("observations.txt:{}: {e}", o.line))?;
    }
    Ok(())
}

/// The weights of an observation at corrected coordinates `xy` (its stereo partner's
/// at `other`) by the settings' scheme.
fn observation_weight(
    block: &Block,
    o: &PixelObservation,
    xy: [f64; 2],
    other: Option<[f64; 2]>,
) -> [f64; 2] {
    let s = &block.settings;
    match s.weighting {
        Weighting::Sigma => {
            let cam = block.rig.interior(o.camera);
            let sx = s.sigma_px * cam.pixel_size_mm[0];
            let sy = s.sigma_px * cam.pixel_size_mm[1];
            [1.0 / (sx * sx), 1.0 / (sy * sy)]
        }
        Weighting::Parallax => {
            // Parallax = left minus right whichever image this is.
            let (l, r) = match (o.camera, other) {
                (Camera::Left, Some(q)) => (xy, Some(q)),
                (Camera::Right, Some(q)) => (q, Some(xy)),
                _ => (xy, None),
            };
            weights(Scheme::Parallax, l, r)
        }
        Weighting::Radial => weights(Scheme::Radial, xy, None),
        Weighting::Equal => weights(Scheme::Equal, xy, None),
    }
}

/// Both cameras of every epoch, with their standard deviations (the right camera's
/// propagated from the left's through the adjusted rig).
fn adjusted_images(w: &Window, n_epochs: usize) -> Vec<AdjustedImage> {
    let rig = w.rig();
    let mut images = Vec::new();
    for slot in 0..n_epochs {
        let left = w.epoch_pose(slot).expect("epoch");
        let std = w.epoch_std(slot).unwrap_or([f64::NAN; 6]);
        let right_std = w.epoch_covariance(slot).map_or([f64::NAN; 6], |c| {
            standard_deviations(&right_camera_covariance(&left, &rig, &c))
        });
        let epoch = w.epoch_id(slot).expect("epoch");
        images.push(AdjustedImage {
            epoch,
            camera: Camera::Left,
            pose: left,
            std,
        });
        images.push(AdjustedImage {
            epoch,
            camera: Camera::Right,
            pose: camera_pose(&left, &rig, Camera::Right),
            std: right_std,
        });
    }
    images
}

/// The observations the robust estimator flagged, with their residuals in pixels
/// (observed - computed, columns right, rows down).
fn flagged(w: &Window, block: &Block) -> Vec<Flagged> {
    let mut flagged = Vec::new();
    for (k, o) in w.observations().iter().enumerate() {
        if !o.is_flagged() {
            continue;
        }
        let src = block.observations[o.tag as usize];
        let r = w.residual(k).unwrap_or([f64::NAN; 2]);
        let cam = block.rig.interior(src.camera);
        flagged.push(Flagged {
            obs: src,
            residual_px: [r[0] / cam.pixel_size_mm[0], -r[1] / cam.pixel_size_mm[1]],
        });
    }
    flagged
}

/// The observation file's camera code, `L` or `R`.
pub fn camera_code(c: Camera) -> &'static str {
    match c {
        Camera::Left => "L",
        Camera::Right => "R",
    }
}
