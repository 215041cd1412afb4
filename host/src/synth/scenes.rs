//! The named scenes: rig, street, trajectory and special effects of each.
use super::noise::value2;
use super::path::StreetPath;
use super::scene::{
    build_street, car, vehicle, Primitive, Scene, StreetStyle, VehicleKind, Zone, ZoneKind,
};
use nalgebra::{Matrix3, Vector3};
use phototraverse_core::camera::{rotation, DistortionModel, Interior, Pose, Rig};
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
    /// Moving vehicles.
    pub traffic: Vec<Mover>,
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

/// How a vehicle of a scene moves: street coordinates (arclength, lateral offset
/// positive right) at epoch `k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Along the street in lane `d` at `v` metres per epoch (negative: oncoming).
    Along { s0: f64, v: f64, d: f64 },
    /// Through keyframes `(epoch, arclength, lateral offset)`: monotone cubic in
    /// between (no overshoot), straight on beyond the ends.
    Keys(&'static [(f64, f64, f64)]),
    /// Across the street at arclength `s`: lateral offset `d0 + v k`, held within
    /// `+-reach` (the vehicle waits there).
    Across { s: f64, d0: f64, v: f64, reach: f64 },
}

impl Motion {
    /// `(arclength, lateral offset, heading relative to the street)` at epoch `k`.
    pub fn at(&self, k: f64) -> (f64, f64, f64) {
        use std::f64::consts::PI;
        match *self {
            Motion::Along { s0, v, d } => (s0 + v * k, d, if v < 0.0 { PI } else { 0.0 }),
            Motion::Keys(keys) => {
                let (s, ds) = pchip(keys, k, |q| q.1);
                let (d, dd) = pchip(keys, k, |q| q.2);
                (s, d, dd.atan2(ds))
            }
            Motion::Across { s, d0, v, reach } => {
                let d = (d0 + v * k).clamp(-reach, reach);
                (s, d, v.signum() * 0.5 * PI)
            }
        }
    }
}

/// Value and derivative at `k` of the monotone piecewise-cubic (Fritsch-Carlson)
/// through `(key.0, value(key))`; linear beyond the ends.
fn pchip(keys: &[(f64, f64, f64)], k: f64, value: impl Fn(&(f64, f64, f64)) -> f64) -> (f64, f64) {
    let n = keys.len();
    let x = |i: usize| keys[i].0;
    let y = |i: usize| value(&keys[i]);
    if n == 1 {
        return (y(0), 0.0);
    }
    let slope = |i: usize| (y(i + 1) - y(i)) / (x(i + 1) - x(i));
    let tangent = |i: usize| {
        if i == 0 {
            slope(0)
        } else if i == n - 1 {
            slope(n - 2)
        } else {
            let (a, b) = (slope(i - 1), slope(i));
            if a * b <= 0.0 {
                0.0
            } else {
                2.0 / (1.0 / a + 1.0 / b)
            }
        }
    };
    if k <= x(0) {
        return (y(0) + tangent(0) * (k - x(0)), tangent(0));
    }
    if k >= x(n - 1) {
        return (y(n - 1) + tangent(n - 1) * (k - x(n - 1)), tangent(n - 1));
    }
    let i = (0..n - 1).rfind(|&i| x(i) <= k).unwrap_or(0);
    let h = x(i + 1) - x(i);
    let t = (k - x(i)) / h;
    let (m0, m1) = (tangent(i) * h, tangent(i + 1) * h);
    let (t2, t3) = (t * t, t * t * t);
    let v = (2.0 * t3 - 3.0 * t2 + 1.0) * y(i)
        + (t3 - 2.0 * t2 + t) * m0
        + (-2.0 * t3 + 3.0 * t2) * y(i + 1)
        + (t3 - t2) * m1;
    let dv = ((6.0 * t2 - 6.0 * t) * y(i)
        + (3.0 * t2 - 4.0 * t + 1.0) * m0
        + (-6.0 * t2 + 6.0 * t) * y(i + 1)
        + (3.0 * t2 - 2.0 * t) * m1)
        / h;
    (v, dv)
}

/// A moving vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mover {
    pub kind: VehicleKind,
    pub shade: f32,
    pub motion: Motion,
}

const fn along(kind: VehicleKind, shade: f32, s0: f64, v: f64, d: f64) -> Mover {
    Mover {
        kind,
        shade,
        motion: Motion::Along { s0, v, d },
    }
}

const fn across(kind: VehicleKind, shade: f32, s: f64, d0: f64, v: f64) -> Mover {
    Mover {
        kind,
        shade,
        motion: Motion::Across {
            s,
            d0,
            v,
            reach: 52.0,
        },
    }
}

/// The `traffic` scene's vehicles. The rig drives 1 m per epoch (arclength = epoch)
/// 1.28 m right of the centre line; lanes at -1.75 (oncoming) and +1.75 m; cross
/// streets at 39..51 m and 129..141 m.
pub const TRAFFIC: [Mover; 8] = [
    // A van overtaking us on the left (passing at epoch 8), into our lane at epochs
    // 18..28, braking: we close in to 4 m (epoch 62), then it pulls away.
    Mover {
        kind: VehicleKind::Van,
        shade: 0.55,
        motion: Motion::Keys(&[
            (0.0, -10.0, -1.75),
            (18.0, 29.6, -1.75),
            (28.0, 50.0, 1.75),
            (40.0, 57.5, 1.75),
            (52.0, 61.6, 1.75),
            (60.0, 66.8, 1.75),
            (72.0, 81.0, 1.75),
            (100.0, 128.0, 1.75),
        ]),
    },
    // Oncoming, passing us at epochs 2 (car), 58 (a bus, while the van is closest), 75
    // (car) and 86 (van).
    along(VehicleKind::Car, 0.7, 5.0, -1.0, -1.75),
    along(VehicleKind::Bus, 0.45, 122.0, -1.0, -1.75),
    along(VehicleKind::Car, 0.2, 150.0, -1.0, -1.75),
    along(VehicleKind::Van, 0.75, 190.0, -1.2, -1.75),
    // Crossing ahead at the first cross street: a van left to right (in the middle at
    // epoch 5), a car right to left (epoch 16); at the second a bus left to right
    // (epoch 95).
    across(VehicleKind::Van, 0.6, 43.5, -5.5, 1.1),
    across(VehicleKind::Car, 0.25, 46.5, 20.8, -1.3),
    across(VehicleKind::Bus, 0.35, 136.5, -95.0, 1.0),
];

/// Cross streets of `traffic`: at 45 and 135 m (the zebra crossings), 12 m wide,
/// reaching 60 m to each side.
fn traffic_style() -> StreetStyle {
    let crossing = |s: f64| Zone {
        s0: s - 6.0,
        s1: s + 6.0,
        kind: ZoneKind::Crossing { length: 60.0 },
    };
    StreetStyle {
        zones: vec![crossing(45.0), crossing(135.0)],
        ..StreetStyle::default()
    }
}

/// Time between epochs of `seed2006`, s: its capture took a new base every 5 frames
/// of a 30 fps camera, so its 0.915 m per epoch is 5.49 m/s (19.76 km/h).
pub const SEED2006_EPOCH_S: f64 = 5.0 / 30.0;

/// Default epochs of `drive`: 1.2 km at 2 m per epoch.
pub const DRIVE_FRAMES: usize = 600;

/// A street's pieces `(length, turn angle)` and grade knots `(arclength, grade)`.
type Layout = (Vec<(f64, f64)>, Vec<(f64, f64)>);

/// The `drive` street: four turns of 25, 20, 60 and 40 m radius between straights
/// (left, right, right, left), a 3 % climb, a 4 % descent, a 2.5 % climb and a 3 %
/// descent.
fn drive_layout(s_end: f64) -> Layout {
    // (length, signed turn angle): a circular piece of length L and angle a has radius L/|a|.
    let arc = |radius: f64, angle: f64| (radius * angle.abs(), angle);
    let pieces = vec![
        (100.0, 0.0),
        arc(25.0, -FRAC_PI_2),
        (160.0, 0.0),
        arc(20.0, FRAC_PI_2),
        (260.0, 0.0),
        arc(60.0, FRAC_PI_2),
        (150.0, 0.0),
        arc(40.0, -FRAC_PI_2),
        ((s_end - 670.0 - 145.0 * FRAC_PI_2).max(200.0), 0.0),
    ];
    let grades = vec![
        (0.0, 0.0),
        (40.0, 0.03),
        (120.0, 0.03),
        (160.0, 0.0),
        (360.0, 0.0),
        (400.0, -0.04),
        (520.0, -0.04),
        (560.0, 0.0),
        (700.0, 0.0),
        (740.0, 0.025),
        (820.0, 0.025),
        (860.0, 0.0),
        (960.0, 0.0),
        (1000.0, -0.03),
        (1080.0, -0.03),
        (1120.0, 0.0),
    ];
    (pieces, grades)
}

/// The `drive` corridor: a street narrower than the default (facades 7 m from the
/// centre line, everything within 20 m of it: the smallest turn radius), two narrow
/// stretches (facades 5.3..6.3 m from the centre line, 4..5 m from the camera on the
/// right; one through the 20 m turn) and open country (fields, buildings 30..110 m away).
fn drive_style() -> StreetStyle {
    let narrow = ZoneKind::Narrow {
        facade: 5.3,
        back: 15.0,
    };
    StreetStyle {
        ground_half_width: 16.0,
        facade_offset: 7.0,
        gap_probability: 0.4,
        back_wall_offset: 17.0,
        zones: vec![
            Zone {
                s0: 145.0,
                s1: 345.0,
                kind: narrow,
            },
            Zone {
                s0: 350.0,
                s1: 585.0,
                kind: ZoneKind::Open {
                    verge: 7.0,
                    field: 150.0,
                    near: 30.0,
                    far: 110.0,
                },
            },
            Zone {
                s0: 950.0,
                s1: 1100.0,
                kind: narrow,
            },
        ],
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
        radial: [0.0; 3],
        decentering: [0.0; 2],
        distortion_model: DistortionModel::Correction,
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
            let rig = seed000_rig();
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
    } else if name == "traffic" {
        style = traffic_style();
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
        dt: if name == "seed2006" {
            SEED2006_EPOCH_S
        } else {
            0.1
        },
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
            for (i, m) in self.traffic.iter().enumerate() {
                let (s, d, turn) = m.motion.at(k);
                let st = path.station(s);
                vehicle(
                    m.kind,
                    st.offset(d),
                    st.heading + turn,
                    m.shade,
                    4243 + i as u32,
                    false,
                    u32::MAX - 16 - 4 * i as u32,
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

/// Seed 000's Quadro 1 rig at the 576x384 format of its experiments: two cameras
/// with their calibrated lenses, 0.40 m apart, converging by 0.3 deg.
pub fn seed000_rig() -> Rig {
    let left = Interior {
        width_px: 576,
        height_px: 384,
        pixel_size_mm: [0.0387, 0.0387],
        focal_mm: 34.6041,
        principal_point_mm: [0.4171, -0.3096],
        radial: [-3.3147e-05, 1.30582e-07, 0.0],
        decentering: [9.086e-05, -7.7278e-05],
        distortion_model: DistortionModel::Correction,
    };
    let right = Interior {
        focal_mm: 35.1727,
        principal_point_mm: [0.2309, -0.1701],
        radial: [-3.7141e-05, 1.77645e-07, 0.0],
        decentering: [7.00283e-05, -1.4916e-05],
        ..left
    };
    Rig {
        left,
        right,
        relative_angles: [0.0, (-0.3f64).to_radians(), 0.0],
        base_m: [0.40, 0.0, 0.0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::geometry::{Shape, V3};
    use crate::synth::material::Material;

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
        assert!(p.frames >= 500);
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
        // Four turns of 20..60 m (steps across a turn's ends see part of it only).
        let lo = radii.iter().cloned().fold(f64::MAX, f64::min);
        assert!((19.9..=20.1).contains(&lo), "{lo}");
        let near = |r: f64| radii.iter().filter(|&&x| (x - r).abs() < 0.1).count();
        assert!(
            near(20.0) >= 30 && near(25.0) >= 38 && near(40.0) >= 61 && near(60.0) >= 93,
            "{} {} {} {}",
            near(20.0),
            near(25.0),
            near(40.0),
            near(60.0)
        );
        assert!(radii.iter().filter(|&&r| r > 60.1).count() <= 8);
        // It climbs and descends, at a few percent.
        let z: Vec<f64> = p
            .stations
            .iter()
            .map(|&s| path.station(s).offset(0.0)[2])
            .collect();
        let (zmin, zmax) = z
            .iter()
            .fold((f64::MAX, f64::MIN), |a, &v| (a.0.min(v), a.1.max(v)));
        assert!(zmax - zmin > 3.0, "{zmin} .. {zmax}");
        let grades: Vec<f64> = p.stations.iter().map(|&s| path.station(s).grade).collect();
        assert!(grades.iter().all(|g| g.abs() <= 0.04 + 1e-12));
        assert!(grades.iter().any(|&g| g > 0.029) && grades.iter().any(|&g| g < -0.039));
    }

    /// `(arclength, lateral offset)` of a primitive's first vertex.
    fn street_coords(path: &StreetPath, prim: &Primitive, near_s: f64) -> Option<(f64, f64)> {
        let o = match &prim.shape {
            Shape::Polygon { origin, .. } => [origin[0], origin[1]],
            Shape::Cylinder { centre, .. } => *centre,
            Shape::Disc { centre, .. } => [centre[0], centre[1]],
        };
        Some(path.local(path.segment_index(near_s), o))
    }

    #[test]
    fn the_drive_has_narrow_streets_and_open_country() {
        let p = plan("drive", None, 1).unwrap();
        let path = p.scene.path.as_ref().unwrap();
        // Facades (the walls facing the street) seen from the camera, 1.28 m right of
        // the centre line: by horizontal rays to the right.
        let side_hit = |s: f64, dir: f64| {
            let st = path.station(s);
            let o = st.offset(p.lane);
            let origin = V3::new(o[0], o[1], o[2] + 1.65);
            let r = st.right();
            let d = V3::new(dir * r[0], dir * r[1], 0.0);
            p.scene
                .prims
                .iter()
                .filter(|q| matches!(q.material, Material::Facade { .. }))
                .filter_map(|q| q.shape.intersect(&origin, &d, 1e9).map(|h| h.t))
                .fold(f64::INFINITY, f64::min)
        };
        // Narrow stretches: facades 4..5 m away on the right where there is no gap.
        for (s0, s1) in [(150.0, 295.0), (955.0, 1095.0)] {
            let hits: Vec<f64> = (0..30)
                .map(|i| side_hit(s0 + (s1 - s0) * i as f64 / 29.0, 1.0))
                .collect();
            let close = hits.iter().filter(|&&t| (3.9..=5.1).contains(&t)).count();
            assert!(close >= 18, "{s0}..{s1}: {hits:?}");
            assert!(hits.iter().all(|&t| t > 3.9), "{hits:?}");
        }
        // Elsewhere on the street, facades 5.7..7.3 m away on the right.
        let hits: Vec<f64> = (0..30)
            .map(|i| side_hit(700.0 + 4.0 * i as f64, 1.0))
            .collect();
        assert!(hits.iter().filter(|&&t| (5.6..=7.3).contains(&t)).count() >= 15);
        // Open country (350..585 m): no facade within 25 m of the road, buildings
        // 30..125 m away, fields out to 100 m and more on both sides.
        let mut far = 0;
        let mut field = [0.0f64; 2];
        for q in &p.scene.prims {
            let Some((s, d)) = street_coords(path, q, 470.0) else {
                continue;
            };
            if !(352.0..583.0).contains(&s) {
                continue;
            }
            match q.material {
                Material::Facade { .. } => {
                    assert!(d.abs() > 25.0, "facade at s {s} d {d}");
                    far += usize::from(d.abs() > 30.0 && d.abs() < 125.0);
                }
                Material::Field { .. } => {
                    if let Shape::Polygon { verts, count, .. } = &q.shape {
                        let len = (0..*count as usize)
                            .map(|i| (verts[i][0].powi(2) + verts[i][1].powi(2)).sqrt())
                            .fold(0.0, f64::max);
                        field[usize::from(d > 0.0)] = field[usize::from(d > 0.0)].max(len);
                    }
                }
                _ => {}
            }
        }
        assert!(far >= 5 * 8, "{far} faces of distant buildings");
        assert!(field[0] > 100.0 && field[1] > 100.0, "{field:?}");
    }

    #[test]
    fn traffic_moves_through_the_scene() {
        let p = plan("traffic", None, 1).unwrap();
        assert_eq!(p.moving(0.0).len(), p.moving(50.0).len());
        assert!(p.moving(0.0).len() >= 5 * TRAFFIC.len());
        assert_ne!(p.moving(0.0), p.moving(1.0), "the vehicles move");
        // The van: overtakes on the left, then ahead in our lane, 4 m at its closest.
        let van = |k: f64| TRAFFIC[0].motion.at(k);
        assert!(van(0.0).0 < 0.0 && van(0.0).1 < 0.0);
        let gap = |k: f64| van(k).0 - 2.6 - p.station_at(k);
        let closest = (30..100).map(|k| gap(k as f64)).fold(f64::MAX, f64::min);
        assert!((closest - 4.0).abs() < 0.05, "{closest}");
        assert!((van(40.0).1 - 1.75).abs() < 1e-9);
        // Oncoming vehicles face us, crossing ones face across.
        assert!((TRAFFIC[2].motion.at(10.0).2 - std::f64::consts::PI).abs() < 1e-12);
        assert!((TRAFFIC[5].motion.at(5.0).2.abs() - FRAC_PI_2).abs() < 1e-12);
    }

    /// Footprint `(s0, s1, d0, d1)` in street coordinates of a vehicle at epoch `k`.
    fn footprint(m: &Mover, k: f64) -> (f64, f64, f64, f64) {
        let (s, d, turn) = m.motion.at(k);
        let [len, width, _] = m.kind.size();
        let (c, sn) = (turn.cos().abs(), turn.sin().abs());
        let (hs, hd) = (0.5 * (len * c + width * sn), 0.5 * (len * sn + width * c));
        (s - hs, s + hs, d - hd, d + hd)
    }

    #[test]
    fn traffic_vehicles_never_meet_in_view() {
        let p = plan("traffic", None, 1).unwrap();
        for q in 0..=4 * p.frames {
            let k = q as f64 / 4.0;
            let cam = p.station_at(k);
            for (i, a) in TRAFFIC.iter().enumerate() {
                let fa = footprint(a, k);
                // Nothing drives into the rig.
                assert!(
                    !(fa.0 < cam + 0.5
                        && fa.1 > cam - 2.0
                        && fa.2 < p.lane + 1.0
                        && fa.3 > p.lane - 1.0),
                    "vehicle {i} hits the rig at epoch {k}"
                );
                for (j, b) in TRAFFIC.iter().enumerate().skip(i + 1) {
                    let fb = footprint(b, k);
                    let (s0, s1) = (fa.0.max(fb.0), fa.1.min(fb.1));
                    let (d0, d1) = (fa.2.max(fb.2), fa.3.min(fb.3));
                    // Overlaps out of view (behind the rig) do not matter.
                    assert!(
                        s0 >= s1 || d0 >= d1 || s1 < cam + 1.0,
                        "vehicles {i} and {j} meet at epoch {k}: {fa:?} {fb:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn traffic_covers_a_sizeable_fraction_at_some_epoch() {
        use crate::synth::render::{render, RenderSettings};
        let p = plan("traffic", None, 1).unwrap();
        // The vehicles alone (no street to hide them), seen by the left camera at 80x60.
        let cam = crate::synth::resample(&p.rig.left, 80, 60).unwrap();
        let settings = RenderSettings {
            edge_ss: 1,
            depth: false,
            ..Default::default()
        };
        let empty = Scene::empty(0.9);
        let coverage: Vec<f64> = (0..p.frames)
            .map(|k| {
                let img = render(
                    &empty,
                    &p.moving(k as f64),
                    &cam,
                    &p.left_pose(k as f64),
                    &settings,
                );
                img.moving_pixels as f64 / (80.0 * 60.0)
            })
            .collect();
        let max = coverage.iter().cloned().fold(0.0, f64::max);
        let at = coverage.iter().position(|&c| c == max).unwrap();
        assert!((0.35..=0.6).contains(&max), "{max} at epoch {at}");
        assert!((45..70).contains(&at), "{at}");
        // Vehicles in view almost all the time.
        assert!(coverage.iter().filter(|&&c| c > 0.01).count() > 90);
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
