//! The named scenes: rig, street, trajectory and special effects of each.
use super::noise::value2;
use super::path::StreetPath;
use super::scene::{build_street, car, Primitive, Scene, StreetStyle};
use nalgebra::{Matrix3, Vector3};
use phototraverse_core::camera::{rotation, Interior, Pose, Rig};
use std::f64::consts::FRAC_PI_2;

/// Names accepted by `synth --scene`.
pub const SCENES: &[&str] = &[
    "straight", "curves", "seed2014", "seed2006", "hard", "handheld", "drive", "traffic",
];

/// Dataset layout written by `synth`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LayoutChoice {
    Kitti,
    Rig,
}

/// Effects of the `hard` scene.
#[derive(Debug, Clone)]
pub struct HardEffects {
    /// `(first epoch, end epoch, gain)`: exposure jumps.
    pub exposure: Vec<(usize, usize, f64)>,
    /// Exposure time as a fraction of the epoch interval (motion blur).
    pub shutter: f64,
    /// Sub-frames averaged over the exposure.
    pub subframes: usize,
    /// The moving vehicle: start arclength, lateral offset, metres per epoch.
    pub vehicle: (f64, f64, f64),
}

/// Everything needed to render a scene.
#[derive(Debug, Clone)]
pub struct ScenePlan {
    pub name: &'static str,
    /// The rig that renders (the truth).
    pub rig: Rig,
    pub frames: usize,
    pub layout: LayoutChoice,
    /// Name images E0001/D0001 (seed style).
    pub seed_names: bool,
    /// Seconds between epochs.
    pub dt: f64,
    pub camera_height: f64,
    /// Lateral offset of the left camera from the centre line (positive right).
    pub lane: f64,
    /// Vibration amplitude of the attitude (degrees) and height (metres).
    pub vibration_deg: f64,
    pub bounce_m: f64,
    /// Arclength of the left camera at each epoch (one more at the end for sub-frames).
    pub stations: Vec<f64>,
    pub scene: Scene,
    pub hard: Option<HardEffects>,
    /// A hand-held rig's walking motion, on top of the vibration.
    pub gait: Option<Gait>,
    /// Moving vehicles: start arclength, lateral offset from the centre line (positive
    /// right), metres per epoch.
    pub traffic: Vec<(f64, f64, f64)>,
    seed: u32,
}

/// The wobble of a rig carried by a walking person: every angle and the position
/// swing with the stride (two steps per cycle), irregularly from one step to the next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gait {
    /// Amplitude on omega, phi and kappa, degrees.
    pub angle_deg: f64,
    /// Amplitude of the vertical bob and the sideways sway, metres.
    pub bob_m: f64,
    pub sway_m: f64,
    /// Length of one step, metres.
    pub step_m: f64,
    /// Constant tilt of the rig above the horizon (seed 000's datum omega 92 deg), degrees.
    pub tilt_deg: f64,
}

impl Gait {
    /// Seed 000's hand-held rig: +-1 deg on every angle, +-3 cm of bob and sway.
    pub const WALKING: Gait = Gait {
        angle_deg: 1.0,
        bob_m: 0.03,
        sway_m: 0.03,
        step_m: 0.7,
        tilt_deg: 2.0,
    };
}

/// The `traffic` scene's vehicles (start arclength, lateral offset, metres per epoch;
/// the rig drives 1 m per epoch in the right lane, 1.28 m right of the centre line): a
/// car ahead in our lane that we close in on from 9 m to 4 m, covering up to 40 % of
/// the image at the end; oncoming cars in the other lane; one overtaking us on the left.
const TRAFFIC: [(f64, f64, f64); 5] = [
    (9.0, 1.75, 0.95),
    (60.0, -1.75, -1.2),
    (150.0, -1.75, -1.5),
    (-12.0, -1.75, 1.35),
    (40.0, -1.0, -0.8),
];

/// Default epochs of `drive`: 1.2 km at 2 m per epoch.
const DRIVE_FRAMES: usize = 600;

/// A street's pieces `(length, turn angle)` and grade knots `(arclength, grade)`.
type Layout = (Vec<(f64, f64)>, Vec<(f64, f64)>);

/// The `drive` street: four turns of 20 to 60 m radius between straights, a climb and
/// a descent.
fn drive_layout(s_end: f64) -> Layout {
    use std::f64::consts::FRAC_PI_2;
    // (length, signed turn angle): a circular piece of length L and angle a has radius L/|a|.
    let arc = |radius: f64, angle: f64| (radius * angle.abs(), angle);
    let pieces = vec![
        (120.0, 0.0),
        arc(20.0, -FRAC_PI_2),
        (150.0, 0.0),
        arc(60.0, FRAC_PI_2),
        (200.0, 0.0),
        arc(35.0, FRAC_PI_2),
        (160.0, 0.0),
        arc(25.0, -FRAC_PI_2),
        ((s_end - 630.0 - 140.0 * FRAC_PI_2).max(200.0), 0.0),
    ];
    let grades = vec![
        (0.0, 0.0),
        (250.0, 0.04),
        (400.0, 0.04),
        (450.0, 0.0),
        (700.0, 0.0),
        (760.0, -0.05),
        (900.0, -0.05),
        (950.0, 0.0),
    ];
    (pieces, grades)
}

/// The `drive` corridor: narrower than the default street, everything within the
/// smallest turn radius (20 m) of the centre line, with more gaps between buildings.
fn drive_style() -> StreetStyle {
    StreetStyle {
        ground_half_width: 16.0,
        facade_offset: 7.0,
        gap_probability: 0.4,
        back_wall_offset: 17.0,
        ..StreetStyle::default()
    }
}

fn pinhole_mm(w: u32, h: u32, pixel: [f64; 2], f: f64) -> Interior {
    Interior {
        width_px: w,
        height_px: h,
        pixel_size_mm: pixel,
        focal_mm: f,
        principal_point_mm: [0.0; 2],
        radial: [0.0; 2],
        decentering: [0.0; 2],
    }
}

/// The plan of scene `name` with `frames` epochs (default per scene when None).
pub fn plan(name: &str, frames: Option<usize>, seed: u64) -> Result<ScenePlan, String> {
    let cam640 = pinhole_mm(640, 480, [0.01, 0.01], 5.0);
    let (name, rig, default_frames, layout): (&'static str, Rig, usize, LayoutChoice) = match name {
        "straight" => (
            "straight",
            Rig::rectified(cam640, 0.94),
            100,
            LayoutChoice::Kitti,
        ),
        "curves" => (
            "curves",
            Rig::rectified(cam640, 0.94),
            220,
            LayoutChoice::Kitti,
        ),
        "hard" => (
            "hard",
            Rig::rectified(cam640, 0.94),
            120,
            LayoutChoice::Kitti,
        ),
        "seed2014" | "handheld" => {
            let px = [0.0387, 0.0387];
            let left = Interior {
                width_px: 576,
                height_px: 384,
                pixel_size_mm: px,
                focal_mm: 34.6041,
                principal_point_mm: [0.4171, -0.3096],
                radial: [-3.3147e-05, 1.30582e-07],
                decentering: [9.086e-05, -7.7278e-05],
            };
            let right = Interior {
                focal_mm: 35.1727,
                principal_point_mm: [0.2309, -0.1701],
                radial: [-3.7141e-05, 1.77645e-07],
                decentering: [7.00283e-05, -1.4916e-05],
                ..left
            };
            let rig = Rig {
                left,
                right,
                relative_angles: [0.0, (-0.3f64).to_radians(), 0.0],
                base_m: [0.40, 0.0, 0.0],
            };
            if name == "handheld" {
                ("handheld", rig, 100, LayoutChoice::Rig)
            } else {
                ("seed2014", rig, 100, LayoutChoice::Rig)
            }
        }
        "traffic" => (
            "traffic",
            Rig::rectified(cam640, 0.94),
            100,
            LayoutChoice::Kitti,
        ),
        "drive" => (
            "drive",
            Rig::rectified(cam640, 0.94),
            DRIVE_FRAMES,
            LayoutChoice::Kitti,
        ),
        "seed2006" => {
            let cam = pinhole_mm(720, 480, [0.0067, 0.0075], 5.9);
            (
                "seed2006",
                Rig::rectified(cam, 0.94),
                100,
                LayoutChoice::Rig,
            )
        }
        other => {
            return Err(format!(
                "unknown scene `{other}` (one of {})",
                SCENES.join(", ")
            ))
        }
    };
    let frames = frames.unwrap_or(default_frames).max(1);
    // Metres per epoch.
    let speed = |k: usize| -> f64 {
        match name {
            "curves" => 1.0 + 0.5 * (2.0 * std::f64::consts::PI * k as f64 / 40.0).sin(),
            "seed2006" => 0.915,
            "drive" => 2.0,
            _ => 1.0,
        }
    };
    let mut stations = Vec::with_capacity(frames + 1);
    let mut s = 0.0;
    for k in 0..=frames {
        stations.push(s);
        s += speed(k);
    }
    let s_end = s + 160.0;
    let (pieces, grades) = if name == "drive" {
        drive_layout(s_end)
    } else if name == "curves" {
        let arc = 30.0 * FRAC_PI_2;
        let pieces = vec![
            (30.0, 0.0),
            (arc, -FRAC_PI_2),
            (40.0, 0.0),
            (arc, FRAC_PI_2),
            ((s_end - 80.0 - 2.0 * arc).max(60.0), 0.0),
        ];
        let grades = vec![
            (0.0, 0.0),
            (15.0, 0.02),
            (60.0, 0.02),
            (80.0, -0.02),
            (130.0, -0.02),
            (150.0, 0.0),
        ];
        (pieces, grades)
    } else {
        (vec![(s_end, 0.0)], vec![])
    };
    let path = StreetPath::from_pieces(-40.0, &pieces, grades);
    let mut style = StreetStyle::default();
    if name == "drive" {
        style = drive_style();
    }
    let mut hard = None;
    if name == "hard" {
        style.textureless = Some((60.0, 85.0));
        hard = Some(HardEffects {
            exposure: vec![(25, 40, 1.3), (70, 80, 0.7)],
            shutter: 0.1,
            subframes: 3,
            vehicle: (12.0, -1.75, 1.25),
        });
    }
    let scene = build_street(path, &style, seed);
    let (camera_height, lane) = match name {
        "seed2006" => (2.2, 1.75 - 0.47),
        "seed2014" | "handheld" => (1.6, 1.75 - 0.2),
        _ => (1.65, 1.75 - 0.47),
    };
    Ok(ScenePlan {
        name,
        rig,
        frames,
        layout,
        seed_names: name == "seed2014",
        dt: 0.1,
        camera_height,
        lane,
        vibration_deg: if name == "hard" { 0.3 } else { 0.15 },
        bounce_m: 0.01,
        gait: (name == "handheld").then_some(Gait::WALKING),
        traffic: if name == "traffic" {
            TRAFFIC.to_vec()
        } else {
            Vec::new()
        },
        stations,
        scene,
        hard,
        seed: seed as u32,
    })
}

impl ScenePlan {
    /// Arclength at a fractional epoch.
    pub fn station_at(&self, k: f64) -> f64 {
        let k = k.max(0.0);
        let i = (k.floor() as usize).min(self.stations.len() - 2);
        let t = k - i as f64;
        self.stations[i] + (self.stations[i + 1] - self.stations[i]) * t
    }

    /// Pose of the left camera at (fractional) epoch `k`: on the lane, at camera
    /// height, looking along the street with its grade, plus smooth vibration.
    pub fn left_pose(&self, k: f64) -> Pose {
        let s = self.station_at(k);
        let path = self.scene.path.as_ref().expect("street scenes have a path");
        let st = path.station(s);
        let p = st.offset(self.lane);
        let fwd = Vector3::new(st.forward()[0], st.forward()[1], st.grade).normalize();
        let right = fwd.cross(&Vector3::z()).normalize();
        let up = right.cross(&fwd);
        // Rows of M are the camera axes (x right, y up, z backward) in object space.
        let m = Matrix3::from_rows(&[right.transpose(), up.transpose(), (-fwd).transpose()]);
        // Vibration: smooth in distance (a few metres), deterministic for the seed.
        let a = self.vibration_deg.to_radians();
        let vib = |j: u32| value2(s / 2.5, j as f64 * 3.7, self.seed.wrapping_add(j));
        let mut r = rotation(a * vib(1), a * vib(2), 0.5 * a * vib(3));
        let mut z = p[2] + self.camera_height + self.bounce_m * vib(4);
        let mut centre = [p[0], p[1], z];
        if let Some(g) = &self.gait {
            // Stride phase with an irregular step; each angle swings with the stride
            // and wanders from step to step.
            let step = s / g.step_m;
            let phase = std::f64::consts::PI * (step + 0.15 * value2(step, 9.1, self.seed));
            let wander =
                |j: u32| value2(step * 0.7, j as f64 * 5.3, self.seed.wrapping_add(20 + j));
            let ga = g.angle_deg.to_radians();
            let swing = |j: u32, q: f64| ga * (0.7 * (phase + q).sin() + 0.3 * wander(j));
            let tilt = g.tilt_deg.to_radians();
            r = rotation(tilt + swing(1, 0.0), swing(2, 1.3), swing(3, 2.1)) * r;
            z += g.bob_m * (2.0 * phase).cos();
            let sway = g.sway_m * phase.sin();
            centre = [p[0] + right[0] * sway, p[1] + right[1] * sway, z];
        }
        Pose::from_rotation(&(r * m), centre)
    }

    /// Moving objects at (fractional) epoch `k`.
    pub fn moving(&self, k: f64) -> Vec<Primitive> {
        let mut out = Vec::new();
        if let (Some(h), Some(path)) = (&self.hard, self.scene.path.as_ref()) {
            let (s0, d, v) = h.vehicle;
            car(
                path,
                s0 + v * k,
                d,
                0.7,
                4242,
                false,
                u32::MAX - 8,
                &mut out,
            );
        }
        if let Some(path) = self.scene.path.as_ref() {
            for (i, &(s0, d, v)) in self.traffic.iter().enumerate() {
                let shade = 0.2 + 0.15 * i as f32;
                let group = u32::MAX - 16 - 2 * i as u32;
                car(
                    path,
                    s0 + v * k,
                    d,
                    shade,
                    4243 + i as u32,
                    false,
                    group,
                    &mut out,
                );
            }
        }
        out
    }

    /// Exposure gain of epoch `k` from the scene's effects.
    pub fn exposure(&self, k: usize) -> f64 {
        self.hard.as_ref().map_or(1.0, |h| {
            h.exposure
                .iter()
                .find(|(a, b, _)| k >= *a && k < *b)
                .map_or(1.0, |e| e.2)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_scene_plans() {
        for name in SCENES {
            let p = plan(name, Some(5), 1).unwrap();
            assert_eq!(p.frames, 5);
            assert!(p.rig.validate().is_ok());
            let pose = p.left_pose(0.0);
            // Level-ish camera looking along +Y at about camera height (the hand-held
            // rig tilted by 2 deg and swinging by up to 1 deg).
            let tol = if p.gait.is_some() { 3.5 } else { 1.0 };
            assert!(
                (pose.omega.to_degrees() - 90.0).abs() < tol,
                "{name}: {pose:?}"
            );
            assert!((pose.centre[2] - p.camera_height).abs() < 0.05);
        }
        assert!(plan("nope", None, 1).is_err());
    }

    #[test]
    fn the_drive_is_a_kilometre_with_four_tight_turns() {
        let p = plan("drive", None, 1).unwrap();
        let path = p.scene.path.as_ref().unwrap();
        let length = p.stations.last().unwrap() - p.stations[0];
        assert!(length >= 1000.0, "{length} m");
        let steps: Vec<f64> = p.stations.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(steps.iter().all(|s| (s - 2.0).abs() < 1e-9));
        // Radii from the heading change over 1 m along the driven stretch.
        let mut radii = Vec::new();
        let mut s = 0.0;
        while s < length {
            let dh = path.station(s + 1.0).heading - path.station(s).heading;
            if dh.abs() > 1e-6 {
                radii.push(1.0 / dh.abs());
            }
            s += 1.0;
        }
        // Every turn is 20..60 m (steps across a turn's ends see part of it only).
        let lo = radii.iter().cloned().fold(f64::MAX, f64::min);
        let near = |r: f64| radii.iter().filter(|&&x| (x - r).abs() < 0.1).count();
        assert!((19.9..=20.1).contains(&lo), "{lo}");
        assert!(
            near(20.0) >= 25 && near(60.0) >= 80,
            "{} {}",
            near(20.0),
            near(60.0)
        );
        assert!(near(25.0) >= 30 && near(35.0) >= 45);
        // It climbs and descends.
        let z: Vec<f64> = p
            .stations
            .iter()
            .map(|&s| path.station(s).offset(0.0)[2])
            .collect();
        let (zmin, zmax) = z
            .iter()
            .fold((f64::MAX, f64::MIN), |a, &v| (a.0.min(v), a.1.max(v)));
        assert!(zmax - zmin > 3.0, "{zmin} .. {zmax}");
    }

    #[test]
    fn traffic_moves_through_the_scene() {
        let p = plan("traffic", None, 1).unwrap();
        assert_eq!(p.moving(0.0).len(), p.moving(50.0).len());
        assert!(p.moving(0.0).len() >= 2 * TRAFFIC.len());
        assert_ne!(p.moving(0.0), p.moving(1.0), "the cars move");
        // The car ahead in our lane: 9 m ahead at the start, 4 m at the end.
        let ahead = |k: f64| TRAFFIC[0].0 + TRAFFIC[0].2 * k - p.station_at(k);
        assert!((ahead(0.0) - 9.0).abs() < 1e-9 && (ahead(100.0) - 4.0).abs() < 1e-6);
    }

    #[test]
    fn the_hand_held_rig_wobbles_within_its_gait() {
        let p = plan("handheld", Some(100), 1).unwrap();
        let g = p.gait.unwrap();
        let level = plan("seed2014", Some(100), 1).unwrap();
        let (mut max_dw, mut max_dz) = (0.0f64, 0.0f64);
        for k in 0..100 {
            let (a, b) = (p.left_pose(k as f64), level.left_pose(k as f64));
            max_dw = max_dw.max((a.omega - b.omega).to_degrees().abs());
            max_dz = max_dz.max((a.centre[2] - b.centre[2]).abs());
        }
        // The tilt plus a swing of up to the amplitude, and a bob of up to 3 cm.
        assert!(
            max_dw > g.tilt_deg && max_dw < g.tilt_deg + 1.5 * g.angle_deg,
            "{max_dw}"
        );
        assert!(
            max_dz > 0.5 * g.bob_m && max_dz < 1.01 * g.bob_m,
            "{max_dz}"
        );
    }

    #[test]
    fn curves_turn_twice_and_climb() {
        let p = plan("curves", None, 1).unwrap();
        let h = |k: f64| {
            p.scene
                .path
                .as_ref()
                .unwrap()
                .station(p.station_at(k))
                .heading
                .to_degrees()
        };
        let headings: Vec<f64> = (0..p.frames).map(|k| h(k as f64)).collect();
        let min = headings.iter().cloned().fold(f64::MAX, f64::min);
        assert!(
            (min + 90.0).abs() < 1e-6,
            "first turn reaches -90 deg: {min}"
        );
        assert!(
            headings.last().unwrap().abs() < 1e-6,
            "second turn back to 0"
        );
        let steps: Vec<f64> = p.stations.windows(2).map(|w| w[1] - w[0]).collect();
        let (lo, hi) = steps
            .iter()
            .fold((f64::MAX, f64::MIN), |a, &s| (a.0.min(s), a.1.max(s)));
        assert!(lo >= 0.5 - 1e-9 && hi <= 1.5 + 1e-9 && lo < 0.6 && hi > 1.4);
    }
}
