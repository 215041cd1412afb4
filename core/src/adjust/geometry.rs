//! Collinearity for the two cameras of the rig, with the Jacobians the
//! adjustment needs.
//!
//! The unknowns of an epoch are the left camera's `(omega, phi, kappa, X, Y, Z)`.
//! The right camera follows through the rig: `M_R = Mrel M_L`,
//! `C_R = C_L + M_L^T b`, so in the right camera frame
//! `q_R = M_R (P - C_R) = Mrel (M_L (P - C_L) - b) = Mrel (q_L - b)`.
//! Chain rule (q = q_L):
//! - `dq_R/d(angle_L) = Mrel dM_L (P - C_L)`, `dq_R/dC_L = -Mrel M_L`, `dq_R/dP = Mrel M_L`,
//! - `dq_R/d(rel angle) = dMrel (q - b)`, `dq_R/db = -Mrel`.
//!
//! Then `xc = -f u/w`, `yc = -f v/w` as in [`crate::camera`].

use crate::camera::{
    rotation_with_derivatives, Camera, CameraError, Pose, RelativeOrientation, MIN_DEPTH,
};
use nalgebra::{Matrix3, Vector3};

/// A projection through the rig with all its partial derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigProjection {
    /// Corrected photo-coordinates, mm.
    pub xy: [f64; 2],
    /// `d(xc, yc)/d(left omega, phi, kappa, X, Y, Z)`.
    pub d_pose: [[f64; 6]; 2],
    /// `d(xc, yc)/d(rel omega, phi, kappa, bx, by, bz)`; zero for the left camera.
    pub d_rig: [[f64; 6]; 2],
    /// `d(xc, yc)/d(X, Y, Z)` of the point.
    pub d_point: [[f64; 3]; 2],
    /// `d(xc, yc)/d(x0_L, y0_L, f_L, x0_R, y0_R, f_R)`: the interior orientation
    /// corrections (see [`with_interior`]); zero unless they were applied.
    pub d_interior: [[f64; 6]; 2],
}

/// Corrections of both cameras' interior orientation, mm, added to the calibration:
/// `[x0_L, y0_L, f_L, x0_R, y0_R, f_R]` (principal point and focal length).
///
/// The observations are reduced with the calibrated principal point, so an error
/// `dx0 = x0_true - x0_cal` shows as `xc = dx0 - (f_cal + df) u / w`.
pub type InteriorCorrections = [f64; 6];

/// Applies interior `corrections` to `pr`, a projection into `camera` computed with the
/// corrected focal length `focal_mm` (calibrated plus `corrections`): adds the principal
/// point shift and fills `d_interior` (`d xc / d f = xc / f` before the shift).
#[inline(always)]
pub fn with_interior(
    mut pr: RigProjection,
    camera: Camera,
    focal_mm: f64,
    corrections: &InteriorCorrections,
) -> RigProjection {
    let k = 3 * camera as usize;
    for c in 0..2 {
        pr.d_interior[c] = [0.0; 6];
        pr.d_interior[c][k + c] = 1.0;
        pr.d_interior[c][k + 2] = pr.xy[c] / focal_mm;
        pr.xy[c] += corrections[k + c];
    }
    pr
}

/// [`with_interior`] for the coordinates alone.
pub fn shift_principal_point(
    xy: [f64; 2],
    camera: Camera,
    corrections: &InteriorCorrections,
) -> [f64; 2] {
    let k = 3 * camera as usize;
    [xy[0] + corrections[k], xy[1] + corrections[k + 1]]
}

/// Focal length of `camera` with the interior corrections, mm.
pub fn corrected_focal(
    focal_mm: [f64; 2],
    camera: Camera,
    corrections: &InteriorCorrections,
) -> f64 {
    focal_mm[camera as usize] + corrections[3 * camera as usize + 2]
}

/// Projects `point` into `camera` of the rig whose left camera is at `left`.
pub fn project_rig(
    left: &Pose,
    rig: &RelativeOrientation,
    camera: Camera,
    focal_mm: f64,
    point: &[f64; 3],
) -> Result<RigProjection, CameraError> {
    let l = Rotations::new(left.omega, left.phi, left.kappa);
    let r = Rotations::new(rig.angles[0], rig.angles[1], rig.angles[2]);
    let right = right_rotation(&l, &r);
    let rot = EpochRotations {
        left: &l,
        rel: &r,
        right: &right,
    };
    project_epoch(
        &rot,
        &left.centre,
        &rig.base,
        camera,
        focal_mm,
        point,
        Partials::PoseAndRig,
    )
}

/// A rotation `M` and its derivatives by three parameters (the angles, or the
/// window's turn), packed column-major (`[M, dM/d1, dM/d2, dM/d3]`, 9 values each) so
/// a window can cache them per epoch: the sines and matrix products cost more than
/// the projection itself.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Rotations(pub [f64; 36]);

impl Rotations {
    /// `M` and its derivatives by omega, phi and kappa (the rig's relative angles).
    pub fn new(omega: f64, phi: f64, kappa: f64) -> Self {
        let (m, d) = rotation_with_derivatives(omega, phi, kappa);
        Self::pack(&m, &d)
    }

    /// `M` and its derivatives by the object-frame turn of [`super::attitude`], the
    /// window's attitude unknowns.
    pub fn with_turn(omega: f64, phi: f64, kappa: f64) -> Self {
        let (m, d) = super::attitude::with_turn_derivatives(omega, phi, kappa);
        Self::pack(&m, &d)
    }

    fn pack(m: &Matrix3<f64>, d: &[Matrix3<f64>; 3]) -> Self {
        let mut out = [0.0; 36];
        out[..9].copy_from_slice(m.as_slice());
        for k in 0..3 {
            out[9 * (k + 1)..9 * (k + 2)].copy_from_slice(d[k].as_slice());
        }
        Rotations(out)
    }

    fn get(&self, k: usize) -> Matrix3<f64> {
        Matrix3::from_column_slice(&self.0[9 * k..9 * k + 9])
    }
}

/// Only the photo-coordinates (no Jacobians) with precomputed rotations;
/// `None` behind the camera.
#[inline]
pub fn project_xy(
    left: &Rotations,
    centre: &[f64; 3],
    rel: &Rotations,
    base: &[f64; 3],
    camera: Camera,
    focal_mm: f64,
    point: &[f64; 3],
) -> Option<[f64; 2]> {
    let (ml, mr) = (left.get(0), rel.get(0));
    project_xy_with(&ml, centre, &mr, base, camera, focal_mm, point)
}

/// [`project_xy`] with the rotation matrices alone (`M` of the left camera and of the
/// rig, as [`crate::camera::rotation`] gives them: no derivatives needed).
#[inline]
pub fn project_xy_with(
    ml: &Matrix3<f64>,
    centre: &[f64; 3],
    mr: &Matrix3<f64>,
    base: &[f64; 3],
    camera: Camera,
    focal_mm: f64,
    point: &[f64; 3],
) -> Option<[f64; 2]> {
    let q = ml * (Vector3::from(*point) - Vector3::from(*centre));
    let q = match camera {
        Camera::Left => q,
        Camera::Right => mr * (q - Vector3::from(*base)),
    };
    let (u, v, w) = (q[0], q[1], q[2]);
    if !(w < -MIN_DEPTH) || !(u.is_finite() && v.is_finite()) {
        return None;
    }
    Some([-focal_mm * u / w, -focal_mm * v / w])
}

/// Which partial derivatives a projection computes: the point's always (the point
/// blocks and the tests of the observations need no more), the pose's and the rig's
/// when camera blocks are built from them. Those not asked for are left at zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Partials {
    Point,
    Pose,
    PoseAndRig,
}

/// An epoch's rotations as a projection uses them: the left camera's [`Rotations`],
/// the rig's, and the right camera's rotation `M_rel M_left` (column-major), which
/// a window caches per epoch rather than multiply it out for every observation.
#[derive(Debug, Clone, Copy)]
pub struct EpochRotations<'r> {
    pub left: &'r Rotations,
    pub rel: &'r Rotations,
    pub right: &'r [f64; 9],
}

/// `M_rel M_left` of [`EpochRotations::right`].
pub fn right_rotation(left: &Rotations, rel: &Rotations) -> [f64; 9] {
    let mut out = [0.0; 9];
    out.copy_from_slice((rel.get(0) * left.get(0)).as_slice());
    out
}

/// [`project_rig`] with an epoch's rotations precomputed ([`EpochRotations`]).
#[inline(always)]
pub fn project_epoch(
    rot: &EpochRotations,
    centre: &[f64; 3],
    base: &[f64; 3],
    camera: Camera,
    focal_mm: f64,
    point: &[f64; 3],
    partials: Partials,
) -> Result<RigProjection, CameraError> {
    let (left, rel) = (rot.left, rot.rel);
    let ml = left.get(0);
    let d = Vector3::from(*point) - Vector3::from(*centre);
    let q = ml * d;
    let angles = partials >= Partials::Pose;
    let dml = |k: usize| left.get(k + 1) * d;
    // Camera-frame point, its derivatives w.r.t. pose angles, centre/point (3x3), rig.
    let (qc, dq_ang, dq_point, dq_rig): (
        Vector3<f64>,
        [Vector3<f64>; 3],
        Matrix3<f64>,
        [Vector3<f64>; 6],
    ) = match camera {
        Camera::Left => (
            q,
            if angles {
                [dml(0), dml(1), dml(2)]
            } else {
                [Vector3::zeros(); 3]
            },
            ml,
            [Vector3::zeros(); 6],
        ),
        Camera::Right => {
            let mr = rel.get(0);
            let qb = q - Vector3::from(*base);
            let dq_rig = if partials == Partials::PoseAndRig {
                [
                    rel.get(1) * qb,
                    rel.get(2) * qb,
                    rel.get(3) * qb,
                    -mr.column(0).into_owned(),
                    -mr.column(1).into_owned(),
                    -mr.column(2).into_owned(),
                ]
            } else {
                [Vector3::zeros(); 6]
            };
            (
                mr * qb,
                if angles {
                    [mr * dml(0), mr * dml(1), mr * dml(2)]
                } else {
                    [Vector3::zeros(); 3]
                },
                Matrix3::from_column_slice(rot.right),
                dq_rig,
            )
        }
    };
    let (u, v, w) = (qc[0], qc[1], qc[2]);
    if !(w < -MIN_DEPTH) || !(u.is_finite() && v.is_finite()) {
        return Err(CameraError::BehindCamera);
    }
    let f = focal_mm;
    // d(xc) = (-f/w) du + (f u / w^2) dw, likewise yc with v.
    let gx = Vector3::new(-f / w, 0.0, f * u / (w * w));
    let gy = Vector3::new(0.0, -f / w, f * v / (w * w));
    let mut out = RigProjection {
        xy: [-f * u / w, -f * v / w],
        d_pose: [[0.0; 6]; 2],
        d_rig: [[0.0; 6]; 2],
        d_point: [[0.0; 3]; 2],
        d_interior: [[0.0; 6]; 2],
    };
    for a in 0..3 {
        if angles {
            out.d_pose[0][a] = gx.dot(&dq_ang[a]);
            out.d_pose[1][a] = gy.dot(&dq_ang[a]);
        }
        let col = dq_point.column(a).into_owned();
        out.d_point[0][a] = gx.dot(&col);
        out.d_point[1][a] = gy.dot(&col);
        out.d_pose[0][3 + a] = -out.d_point[0][a];
        out.d_pose[1][3 + a] = -out.d_point[1][a];
    }
    if camera == Camera::Right && partials == Partials::PoseAndRig {
        for (j, dq) in dq_rig.iter().enumerate() {
            out.d_rig[0][j] = gx.dot(dq);
            out.d_rig[1][j] = gy.dot(dq);
        }
    }
    Ok(out)
}

/// Pose of `camera` given the left pose and the rig.
pub fn camera_pose(left: &Pose, rig: &RelativeOrientation, camera: Camera) -> Pose {
    match camera {
        Camera::Left => *left,
        Camera::Right => rig.right_pose(left),
    }
}
