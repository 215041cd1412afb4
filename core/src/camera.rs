//! The photogrammetric camera model and conventions of docs/conventions.md
//! ("Pixel convention", "Interior orientation and distortion", "Rotation and
//! collinearity", "Stereo rig", "KITTI output").
//!
//! - Photo-coordinates in mm, origin at the image centre, x right, y up.
//! - Interior orientation: focal length, principal point, radial (k1, k2, k3) and
//!   decentering (p1, p2) distortion, by default as a *correction of measured
//!   coordinates*; [`DistortionModel::Projection`] holds calibrations made the other
//!   way round (OpenCV, Kalibr `radtan`) exactly.
//! - `M = Rk(kappa) Rp(phi) Rw(omega)` rotates object to camera; collinearity
//!   `(u, v, w) = M (P - C)`, `xc = -f u / w`, `yc = -f v / w`; the camera looks
//!   along its -z axis, so a point in front has `w < 0`.
//! - Object frame: X right along the base, Y forward, Z up, metres.
//!
//! Everything here is `f64`: the adjustment works in it (see `adjust`), and a
//! few microseconds per projection do not matter next to feature extraction.

use nalgebra::{Matrix3, Vector3};

mod rigid;
pub(crate) use rigid::{rigid_fit, RigidMotion};

/// Smallest `-w` (object units along the viewing direction) for a point to count
/// as in front of the camera.
pub const MIN_DEPTH: f64 = 1e-9;

/// Newton steps the inverse distortion may take.
pub const UNDISTORT_MAX_ITER: usize = 20;
/// Convergence tolerance of the inverse distortion, mm.
pub const UNDISTORT_TOL_MM: f64 = 1e-12;

/// Why a camera computation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraError {
    /// Focal length not positive or not finite.
    BadFocal,
    /// Image size zero or pixel size not positive.
    BadFormat,
    /// A parameter is NaN or infinite.
    NotFinite,
    /// The point lies behind the camera or in its principal plane.
    BehindCamera,
    /// The inverse distortion did not converge (distortion too strong for the position).
    DistortionDiverged,
}

impl core::fmt::Display for CameraError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            CameraError::BadFocal => "focal length must be positive and finite",
            CameraError::BadFormat => "image size and pixel size must be positive",
            CameraError::NotFinite => "camera parameter is not finite",
            CameraError::BehindCamera => "point is behind the camera",
            CameraError::DistortionDiverged => "inverse distortion did not converge",
        })
    }
}

/// Which way the distortion polynomials act (docs/conventions.md, "Interior
/// orientation and distortion").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DistortionModel {
    /// The photogrammetric convention: the polynomials of the *measured* reduced
    /// coordinates give their correction, `xc = xb - d(xb)`.
    #[default]
    Correction,
    /// The computer-vision convention (OpenCV, Kalibr `radtan`): the polynomials of
    /// the *ideal* coordinates give where the point is measured, `xb = xc + d(xc)`.
    Projection,
}

/// Interior orientation and image format of one camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interior {
    pub width_px: u32,
    pub height_px: u32,
    /// Pixel size `[sx, sy]`, mm.
    pub pixel_size_mm: [f64; 2],
    /// Calibrated focal length, mm.
    pub focal_mm: f64,
    /// Principal point `[x0, y0]`, mm, in photo-coordinates.
    pub principal_point_mm: [f64; 2],
    /// Radial distortion `[k1 (mm^-2), k2 (mm^-4), k3 (mm^-6)]`.
    pub radial: [f64; 3],
    /// Decentering distortion `[p1, p2]`, mm^-1.
    pub decentering: [f64; 2],
    /// Which way `radial` and `decentering` act.
    pub distortion_model: DistortionModel,
}

/// Indices of the interior parameters in [`Interior::correction_jacobian`].
pub mod io_param {
    pub const X0: usize = 0;
    pub const Y0: usize = 1;
    pub const K1: usize = 2;
    pub const K2: usize = 3;
    pub const P1: usize = 4;
    pub const P2: usize = 5;
    pub const K3: usize = 6;
    /// Number of columns.
    pub const COUNT: usize = 7;
}

/// Grid points per side on which [`Interior::validate`] checks that the distortion
/// can be undone over the whole format.
const FORMAT_CHECK_GRID: usize = 33;
/// Largest disagreement, mm, between a format point and its round trip through
/// [`Interior::correct`] and [`Interior::uncorrect`] that still counts as invertible.
const FORMAT_CHECK_TOL_MM: f64 = 1e-9;

impl Interior {
    /// An ideal pinhole in pixel units: `sx = sy = 1`, principal point at the
    /// image centre, no distortion.
    pub fn pinhole_px(width_px: u32, height_px: u32, focal_px: f64) -> Self {
        Interior {
            width_px,
            height_px,
            pixel_size_mm: [1.0, 1.0],
            focal_mm: focal_px,
            principal_point_mm: [0.0, 0.0],
            radial: [0.0; 3],
            decentering: [0.0, 0.0],
            distortion_model: DistortionModel::Correction,
        }
    }

    /// No lens distortion: correction and its inverse are the identity.
    pub fn is_distortion_free(&self) -> bool {
        self.radial == [0.0; 3] && self.decentering == [0.0; 2]
    }

    /// Checks that the parameters describe a real camera, whose distortion can be
    /// undone everywhere on its format.
    pub fn validate(&self) -> Result<(), CameraError> {
        let values = [
            self.pixel_size_mm[0],
            self.pixel_size_mm[1],
            self.focal_mm,
            self.principal_point_mm[0],
            self.principal_point_mm[1],
            self.radial[0],
            self.radial[1],
            self.radial[2],
            self.decentering[0],
            self.decentering[1],
        ];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(CameraError::NotFinite);
        }
        if self.focal_mm <= 0.0 {
            return Err(CameraError::BadFocal);
        }
        if self.width_px == 0
            || self.height_px == 0
            || self.pixel_size_mm[0] <= 0.0
            || self.pixel_size_mm[1] <= 0.0
        {
            return Err(CameraError::BadFormat);
        }
        self.check_invertible_over_format()
    }

    /// A lens whose distortion folds the format over itself (a polynomial fitted
    /// far beyond its data) has no inverse there: every grid point of the format
    /// must come back from the ideal coordinates to where it was measured.
    fn check_invertible_over_format(&self) -> Result<(), CameraError> {
        if self.is_distortion_free() {
            return Ok(());
        }
        let n = FORMAT_CHECK_GRID;
        let last = (n - 1) as f64;
        for i in 0..n {
            for j in 0..n {
                let c = (self.width_px as f64 - 1.0) * i as f64 / last;
                let r = (self.height_px as f64 - 1.0) * j as f64 / last;
                let [x, y] = self.pixel_to_photo(c, r);
                let [xc, yc] = self.correct(x, y);
                let [xm, ym] = self.uncorrect(xc, yc)?;
                let back =
                    (xm - x).abs() <= FORMAT_CHECK_TOL_MM && (ym - y).abs() <= FORMAT_CHECK_TOL_MM;
                if !back || !self.orientation_preserved(x, y, xc, yc) {
                    return Err(CameraError::DistortionDiverged);
                }
            }
        }
        Ok(())
    }

    /// Whether the distortion keeps its orientation at a point (measured `(x, y)`,
    /// corrected `(xc, yc)`): the Jacobian of the closed-form direction has a positive
    /// determinant. A round trip alone would accept a fold, where Newton finds a root
    /// on the wrong branch.
    fn orientation_preserved(&self, x: f64, y: f64, xc: f64, yc: f64) -> bool {
        let [[a, b], [c, d]] = match self.distortion_model {
            DistortionModel::Correction => self.step_jacobian(
                x - self.principal_point_mm[0],
                y - self.principal_point_mm[1],
                -1.0,
            ),
            DistortionModel::Projection => self.step_jacobian(xc, yc, 1.0),
        };
        a * d - b * c > 0.0
    }

    /// The Jacobian `I + sign J_d` of `z + sign d(z)` at `z`: Newton's step matrix of
    /// [`Self::solve_distorted`], and the map whose determinant tells a fold.
    fn step_jacobian(&self, zx: f64, zy: f64, sign: f64) -> [[f64; 2]; 2] {
        let j = self.distortion_jacobian(zx, zy);
        [
            [1.0 + sign * j[0][0], sign * j[0][1]],
            [sign * j[1][0], 1.0 + sign * j[1][1]],
        ]
    }

    fn centre_px(&self) -> [f64; 2] {
        [
            (self.width_px as f64 - 1.0) * 0.5,
            (self.height_px as f64 - 1.0) * 0.5,
        ]
    }

    /// Pixel `(c, r)` to photo-coordinates `(x, y)` in mm (not corrected).
    pub fn pixel_to_photo(&self, c: f64, r: f64) -> [f64; 2] {
        let [cc, rc] = self.centre_px();
        [
            (c - cc) * self.pixel_size_mm[0],
            -(r - rc) * self.pixel_size_mm[1],
        ]
    }

    /// Photo-coordinates `(x, y)` in mm to pixel `(c, r)`.
    pub fn photo_to_pixel(&self, x: f64, y: f64) -> [f64; 2] {
        let [cc, rc] = self.centre_px();
        [
            x / self.pixel_size_mm[0] + cc,
            -y / self.pixel_size_mm[1] + rc,
        ]
    }

    /// The distortion polynomials `(dx, dy)` at reduced coordinates `(xb, yb)`
    /// (relative to the principal point): measured ones for
    /// [`DistortionModel::Correction`], ideal ones for [`DistortionModel::Projection`].
    pub fn distortion(&self, xb: f64, yb: f64) -> [f64; 2] {
        let [k1, k2, k3] = self.radial;
        let [p1, p2] = self.decentering;
        let r2 = xb * xb + yb * yb;
        let radial = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        [
            xb * radial + p1 * (r2 + 2.0 * xb * xb) + 2.0 * p2 * xb * yb,
            yb * radial + 2.0 * p1 * xb * yb + p2 * (r2 + 2.0 * yb * yb),
        ]
    }

    /// `d(dx, dy) / d(xb, yb)`, row-major.
    fn distortion_jacobian(&self, xb: f64, yb: f64) -> [[f64; 2]; 2] {
        let [k1, k2, k3] = self.radial;
        let [p1, p2] = self.decentering;
        let r2 = xb * xb + yb * yb;
        let radial = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        let dradial = 2.0 * (k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2); // d(radial)/dxb = dradial * xb
        [
            [
                radial + dradial * xb * xb + 6.0 * p1 * xb + 2.0 * p2 * yb,
                dradial * xb * yb + 2.0 * p1 * yb + 2.0 * p2 * xb,
            ],
            [
                dradial * xb * yb + 2.0 * p1 * yb + 2.0 * p2 * xb,
                radial + dradial * yb * yb + 2.0 * p1 * xb + 6.0 * p2 * yb,
            ],
        ]
    }

    /// Measured photo-coordinates to corrected reduced coordinates `(xc, yc)`:
    /// relative to the principal point and free of lens distortion.
    ///
    /// Closed form for [`DistortionModel::Correction`]. For
    /// [`DistortionModel::Projection`] it is Newton's inverse of `xc + d(xc) = xb`,
    /// which [`Interior::validate`] has checked on a dense grid of the format (it
    /// converges, comes back, and the lens does not fold there); where it does not
    /// converge the last iterate is returned, as OpenCV's `undistortPoints` does.
    pub fn correct(&self, x: f64, y: f64) -> [f64; 2] {
        let xb = x - self.principal_point_mm[0];
        let yb = y - self.principal_point_mm[1];
        match self.distortion_model {
            DistortionModel::Correction => {
                let [dx, dy] = self.distortion(xb, yb);
                [xb - dx, yb - dy]
            }
            DistortionModel::Projection => match self.solve_distorted(xb, yb, 1.0) {
                Ok(xy) | Err(Unsolved(xy)) => xy,
            },
        }
    }

    /// Inverse of [`Interior::correct`]: where a point with corrected coordinates
    /// `(xc, yc)` is measured on the photo.
    ///
    /// Closed form for [`DistortionModel::Projection`]. For
    /// [`DistortionModel::Correction`] it is Newton's method on `xb - d(xb) = xc`
    /// from `xb = xc`. Convergence: the correction map is a contraction wherever
    /// the norm of `d(dx,dy)/d(xb,yb)` stays below 1 (for the seed 000 lens it is
    /// below 0.02 over the whole format), and Newton then converges quadratically;
    /// the iteration stops at a step below [`UNDISTORT_TOL_MM`] and fails after
    /// [`UNDISTORT_MAX_ITER`] steps or on a singular Jacobian, which happens only
    /// far outside the calibrated format.
    pub fn uncorrect(&self, xc: f64, yc: f64) -> Result<[f64; 2], CameraError> {
        if !(xc.is_finite() && yc.is_finite()) {
            return Err(CameraError::NotFinite);
        }
        let [xb, yb] = match self.distortion_model {
            DistortionModel::Projection => {
                let [dx, dy] = self.distortion(xc, yc);
                [xc + dx, yc + dy]
            }
            DistortionModel::Correction => self
                .solve_distorted(xc, yc, -1.0)
                .map_err(|_| CameraError::DistortionDiverged)?,
        };
        Ok([
            xb + self.principal_point_mm[0],
            yb + self.principal_point_mm[1],
        ])
    }

    /// Solves `z + sign d(z) = t` for `z` by Newton's method from `z = t`: the
    /// inverse of whichever direction of the distortion has no closed form.
    fn solve_distorted(&self, tx: f64, ty: f64, sign: f64) -> Result<[f64; 2], Unsolved> {
        let (mut zx, mut zy) = (tx, ty);
        for _ in 0..UNDISTORT_MAX_ITER {
            let [dx, dy] = self.distortion(zx, zy);
            let fx = zx + sign * dx - tx;
            let fy = zy + sign * dy - ty;
            let [[a, b], [c, d]] = self.step_jacobian(zx, zy, sign);
            let det = a * d - b * c;
            // A non-positive determinant is a fold: no root there is the lens's.
            if det.is_nan() || det <= 1e-6 {
                return Err(Unsolved([zx, zy]));
            }
            let sx = (d * fx - b * fy) / det;
            let sy = (a * fy - c * fx) / det;
            zx -= sx;
            zy -= sy;
            if sx.abs() < UNDISTORT_TOL_MM && sy.abs() < UNDISTORT_TOL_MM {
                return Ok([zx, zy]);
            }
        }
        Err(Unsolved([zx, zy]))
    }

    /// Pixel `(c, r)` straight to corrected reduced coordinates, mm.
    pub fn pixel_to_corrected(&self, c: f64, r: f64) -> [f64; 2] {
        let [x, y] = self.pixel_to_photo(c, r);
        self.correct(x, y)
    }

    /// Corrected reduced coordinates to the pixel where they are measured.
    pub fn corrected_to_pixel(&self, xc: f64, yc: f64) -> Result<[f64; 2], CameraError> {
        let [x, y] = self.uncorrect(xc, yc)?;
        Ok(self.photo_to_pixel(x, y))
    }

    /// `d(xc, yc) / d(x0, y0, k1, k2, p1, p2, k3)` at measured photo-coordinates
    /// `(x, y)` (columns in the order of [`io_param`]). The focal length enters
    /// through the projection, see [`Projection::d_focal`].
    pub fn correction_jacobian(&self, x: f64, y: f64) -> [[f64; io_param::COUNT]; 2] {
        let xb = x - self.principal_point_mm[0];
        let yb = y - self.principal_point_mm[1];
        match self.distortion_model {
            DistortionModel::Correction => {
                // xc = xb - d(xb; k) with xb = x - x0.
                let j = self.distortion_jacobian(xb, yb);
                let dk = Self::distortion_parameter_jacobian(xb, yb);
                let mut out = [[0.0; io_param::COUNT]; 2];
                for row in 0..2 {
                    for (col, v) in dk[row].iter().enumerate() {
                        out[row][col] = -v;
                    }
                    out[row][io_param::X0] = -(if row == 0 { 1.0 } else { 0.0 }) + j[row][0];
                    out[row][io_param::Y0] = -(if row == 0 { 0.0 } else { 1.0 }) + j[row][1];
                }
                out
            }
            DistortionModel::Projection => {
                // xc + d(xc; k) = x - x0: d(xc) = (I + J)^-1 (-dx0 - dd/dk dk).
                let [xc, yc] = self.correct(x, y);
                let j = self.distortion_jacobian(xc, yc);
                let (a, b, c, d) = (1.0 + j[0][0], j[0][1], j[1][0], 1.0 + j[1][1]);
                let det = a * d - b * c;
                let inv = [[d / det, -b / det], [-c / det, a / det]];
                let mut rhs = Self::distortion_parameter_jacobian(xc, yc);
                for row in rhs.iter_mut() {
                    for v in row.iter_mut() {
                        *v = -*v;
                    }
                }
                rhs[0][io_param::X0] = -1.0;
                rhs[1][io_param::Y0] = -1.0;
                let mut out = [[0.0; io_param::COUNT]; 2];
                for row in 0..2 {
                    for col in 0..io_param::COUNT {
                        out[row][col] = inv[row][0] * rhs[0][col] + inv[row][1] * rhs[1][col];
                    }
                }
                out
            }
        }
    }

    /// `d(dx, dy) / d(k1, k2, p1, p2, k3)` at reduced coordinates `(u, v)`, in the
    /// columns of [`io_param`] (the principal point's columns zero).
    fn distortion_parameter_jacobian(u: f64, v: f64) -> [[f64; io_param::COUNT]; 2] {
        use io_param::*;
        let r2 = u * u + v * v;
        let mut out = [[0.0; COUNT]; 2];
        for (row, w) in [u, v].into_iter().enumerate() {
            out[row][K1] = w * r2;
            out[row][K2] = w * r2 * r2;
            out[row][K3] = w * r2 * r2 * r2;
        }
        out[0][P1] = r2 + 2.0 * u * u;
        out[0][P2] = 2.0 * u * v;
        out[1][P1] = 2.0 * u * v;
        out[1][P2] = r2 + 2.0 * v * v;
        out
    }
}

/// Newton's inverse of the distortion did not converge; its last iterate.
#[derive(Debug, Clone, Copy)]
struct Unsolved([f64; 2]);

/// `Rw(omega)`, `Rp(phi)`, `Rk(kappa)` and their derivatives, as docs/conventions.md
/// ("Rotation and collinearity") writes them.
fn r_omega(w: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = libm::sincos(w);
    (
        Matrix3::new(1.0, 0.0, 0.0, 0.0, c, s, 0.0, -s, c),
        Matrix3::new(0.0, 0.0, 0.0, 0.0, -s, c, 0.0, -c, -s),
    )
}

fn r_phi(p: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = libm::sincos(p);
    (
        Matrix3::new(c, 0.0, -s, 0.0, 1.0, 0.0, s, 0.0, c),
        Matrix3::new(-s, 0.0, -c, 0.0, 0.0, 0.0, c, 0.0, -s),
    )
}

fn r_kappa(k: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    let (s, c) = libm::sincos(k);
    (
        Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0),
        Matrix3::new(-s, c, 0.0, -c, -s, 0.0, 0.0, 0.0, 0.0),
    )
}

/// `M = Rk(kappa) Rp(phi) Rw(omega)`, object to camera; angles in radians.
pub fn rotation(omega: f64, phi: f64, kappa: f64) -> Matrix3<f64> {
    r_kappa(kappa).0 * r_phi(phi).0 * r_omega(omega).0
}

/// `M` and its derivatives with respect to omega, phi and kappa.
pub fn rotation_with_derivatives(
    omega: f64,
    phi: f64,
    kappa: f64,
) -> (Matrix3<f64>, [Matrix3<f64>; 3]) {
    let (rw, dw) = r_omega(omega);
    let (rp, dp) = r_phi(phi);
    let (rk, dk) = r_kappa(kappa);
    (rk * rp * rw, [rk * rp * dw, rk * dp * rw, dk * rp * rw])
}

/// The rotation `a diag(1, 1, d) b`, `d` the sign of `det(a b)`: the last step of a
/// least-squares rotation (Kabsch, Wahba) from the orthogonal factors of an SVD, with the
/// sign that keeps a reflection out. `None` when it is not finite.
pub fn proper_rotation(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let d = (a * b).determinant().signum();
    let r = a * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * b;
    r.iter().all(|x| x.is_finite()).then_some(r)
}

/// `(omega, phi, kappa)` in radians from `M = Rk Rp Rw`, with `phi` in
/// `[-pi/2, pi/2]`. From `m31 = sin phi`, `m32 = -cos phi sin omega`,
/// `m33 = cos phi cos omega`, `m21 = -sin kappa cos phi`, `m11 = cos kappa cos phi`.
pub fn angles_from_rotation(m: &Matrix3<f64>) -> [f64; 3] {
    let phi = libm::asin(m[(2, 0)].clamp(-1.0, 1.0));
    let omega = libm::atan2(-m[(2, 1)], m[(2, 2)]);
    let kappa = libm::atan2(-m[(1, 0)], m[(0, 0)]);
    [omega, phi, kappa]
}

/// Exterior orientation of one image: angles in radians, perspective centre in metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub omega: f64,
    pub phi: f64,
    pub kappa: f64,
    pub centre: [f64; 3],
}

impl Pose {
    /// From angles in degrees and a centre in metres.
    pub fn from_degrees(omega: f64, phi: f64, kappa: f64, centre: [f64; 3]) -> Self {
        Pose {
            omega: omega.to_radians(),
            phi: phi.to_radians(),
            kappa: kappa.to_radians(),
            centre,
        }
    }

    /// From a rotation matrix `M` (object to camera) and a centre.
    pub fn from_rotation(m: &Matrix3<f64>, centre: [f64; 3]) -> Self {
        let [omega, phi, kappa] = angles_from_rotation(m);
        Pose {
            omega,
            phi,
            kappa,
            centre,
        }
    }

    pub fn rotation(&self) -> Matrix3<f64> {
        rotation(self.omega, self.phi, self.kappa)
    }

    pub fn centre_vec(&self) -> Vector3<f64> {
        Vector3::from(self.centre)
    }

    /// The six parameters in the order of the Jacobians: omega, phi, kappa, X, Y, Z.
    pub fn to_params(&self) -> [f64; 6] {
        let [x, y, z] = self.centre;
        [self.omega, self.phi, self.kappa, x, y, z]
    }

    pub fn from_params(p: &[f64; 6]) -> Self {
        Pose {
            omega: p[0],
            phi: p[1],
            kappa: p[2],
            centre: [p[3], p[4], p[5]],
        }
    }

    /// `(u, v, w) = M (P - C)`: the point in this camera's frame.
    pub fn to_camera(&self, point: &[f64; 3]) -> Vector3<f64> {
        self.rotation() * (Vector3::from(*point) - self.centre_vec())
    }
}

/// A collinearity projection with its analytic Jacobians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Corrected reduced photo-coordinates `(xc, yc)`, mm.
    pub xy: [f64; 2],
    /// `d(xc, yc) / d(omega, phi, kappa, X0, Y0, Z0)`.
    pub d_pose: [[f64; 6]; 2],
    /// `d(xc, yc) / d(X, Y, Z)` of the object point.
    pub d_point: [[f64; 3]; 2],
    /// `d(xc, yc) / df`.
    pub d_focal: [f64; 2],
}

/// Collinearity: corrected reduced photo-coordinates of `point` seen from `pose`
/// with focal length `focal_mm`.
pub fn project(pose: &Pose, focal_mm: f64, point: &[f64; 3]) -> Result<[f64; 2], CameraError> {
    let uvw = pose.to_camera(point);
    if uvw[2].is_nan() || uvw[2] >= -MIN_DEPTH {
        return Err(CameraError::BehindCamera);
    }
    Ok([-focal_mm * uvw[0] / uvw[2], -focal_mm * uvw[1] / uvw[2]])
}

/// Collinearity with the Jacobians with respect to the exterior orientation,
/// the object point and the focal length.
pub fn project_with_jacobians(
    pose: &Pose,
    focal_mm: f64,
    point: &[f64; 3],
) -> Result<Projection, CameraError> {
    let rotation = rotation_with_derivatives(pose.omega, pose.phi, pose.kappa);
    project_with_rotation(pose, rotation, focal_mm, point)
}

/// [`project_with_jacobians`] with the pose's rotation `M` and its derivatives by any
/// three attitude parameters (the angles, or an adjustment's own), which `d_pose`'s
/// first three columns then follow.
pub fn project_with_rotation(
    pose: &Pose,
    (m, dm): (Matrix3<f64>, [Matrix3<f64>; 3]),
    focal_mm: f64,
    point: &[f64; 3],
) -> Result<Projection, CameraError> {
    let d = Vector3::from(*point) - pose.centre_vec();
    let uvw = m * d;
    let (u, v, w) = (uvw[0], uvw[1], uvw[2]);
    if w.is_nan() || w >= -MIN_DEPTH {
        return Err(CameraError::BehindCamera);
    }
    let f = focal_mm;
    // d(xc) = (-f/w) du + (f u / w^2) dw, and likewise for yc with v.
    let gx = [-f / w, 0.0, f * u / (w * w)];
    let gy = [0.0, -f / w, f * v / (w * w)];
    let chain =
        |g: &[f64; 3], duvw: &Vector3<f64>| g[0] * duvw[0] + g[1] * duvw[1] + g[2] * duvw[2];

    let mut d_pose = [[0.0; 6]; 2];
    let mut d_point = [[0.0; 3]; 2];
    for (a, dma) in dm.iter().enumerate() {
        let duvw = dma * d;
        d_pose[0][a] = chain(&gx, &duvw);
        d_pose[1][a] = chain(&gy, &duvw);
    }
    for k in 0..3 {
        // d(uvw)/dP_k is column k of M; the centre enters with the opposite sign.
        let col = m.column(k).into_owned();
        d_point[0][k] = chain(&gx, &col);
        d_point[1][k] = chain(&gy, &col);
        d_pose[0][3 + k] = -d_point[0][k];
        d_pose[1][3 + k] = -d_point[1][k];
    }
    Ok(Projection {
        xy: [-f * u / w, -f * v / w],
        d_pose,
        d_point,
        d_focal: [-u / w, -v / w],
    })
}

/// Pixel where `point` is measured by a camera with `interior` at `pose`
/// (projection, then distortion and pixel conversion).
pub fn project_to_pixel(
    pose: &Pose,
    interior: &Interior,
    point: &[f64; 3],
) -> Result<[f64; 2], CameraError> {
    let [xc, yc] = project(pose, interior.focal_mm, point)?;
    interior.corrected_to_pixel(xc, yc)
}

/// A calibrated stereo rig: two cameras and the pose of the right one relative to the left.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rig {
    pub left: Interior,
    pub right: Interior,
    /// Relative angles `(omega, phi, kappa)`, radians: `M_R = Mrel M_L`.
    pub relative_angles: [f64; 3],
    /// Base vector `b` in the left camera frame, metres: `C_R = C_L + M_L^T b`.
    pub base_m: [f64; 3],
}

impl Rig {
    /// A rectified rig: identical ideal cameras, no relative rotation, base `(b, 0, 0)`.
    pub fn rectified(camera: Interior, base_m: f64) -> Self {
        Rig {
            left: camera,
            right: camera,
            relative_angles: [0.0; 3],
            base_m: [base_m, 0.0, 0.0],
        }
    }

    /// The interior orientation of `camera`.
    pub fn interior(&self, camera: Camera) -> &Interior {
        match camera {
            Camera::Left => &self.left,
            Camera::Right => &self.right,
        }
    }

    pub fn relative_rotation(&self) -> Matrix3<f64> {
        self.relative().rotation()
    }

    /// Length of the base, metres.
    pub fn base_length(&self) -> f64 {
        self.relative().base_length()
    }

    /// The right camera's orientation relative to the left.
    pub fn relative(&self) -> RelativeOrientation {
        RelativeOrientation::from_rig(self)
    }

    /// Pose of the right camera given the left one.
    pub fn right_pose(&self, left: &Pose) -> Pose {
        self.relative().right_pose(left)
    }

    pub fn validate(&self) -> Result<(), CameraError> {
        self.left.validate()?;
        self.right.validate()?;
        let finite = self
            .relative_angles
            .iter()
            .chain(self.base_m.iter())
            .all(|v| v.is_finite());
        if finite {
            Ok(())
        } else {
            Err(CameraError::NotFinite)
        }
    }
}

/// Which camera of the rig took an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Camera {
    Left = 0,
    Right = 1,
}

impl Camera {
    pub fn from_index(i: u8) -> Option<Camera> {
        match i {
            0 => Some(Camera::Left),
            1 => Some(Camera::Right),
            _ => None,
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }

    /// `left` or `right`, as the outputs' camera columns write it.
    pub fn name(self) -> &'static str {
        match self {
            Camera::Left => "left",
            Camera::Right => "right",
        }
    }
}

/// The right camera's orientation relative to the left (docs/conventions.md, "Stereo
/// rig"): `M_R = Mrel M_L`, `C_R = C_L + M_L^T b`; as adjustable parameters
/// `[w, p, k (rad), bx, by, bz (m)]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeOrientation {
    /// `(omega, phi, kappa)` of `Mrel`, radians.
    pub angles: [f64; 3],
    /// `b` in the left camera frame, metres.
    pub base: [f64; 3],
}

impl RelativeOrientation {
    pub fn from_rig(rig: &Rig) -> Self {
        RelativeOrientation {
            angles: rig.relative_angles,
            base: rig.base_m,
        }
    }

    pub fn to_array(&self) -> [f64; 6] {
        let [a, b, c] = self.angles;
        let [x, y, z] = self.base;
        [a, b, c, x, y, z]
    }

    pub fn from_array(p: &[f64; 6]) -> Self {
        RelativeOrientation {
            angles: [p[0], p[1], p[2]],
            base: [p[3], p[4], p[5]],
        }
    }

    /// Length of the base vector, metres.
    pub fn base_length(&self) -> f64 {
        Vector3::from(self.base).norm()
    }

    pub fn rotation(&self) -> Matrix3<f64> {
        let [w, p, k] = self.angles;
        rotation(w, p, k)
    }

    /// Pose of the right camera given the left one.
    pub fn right_pose(&self, left: &Pose) -> Pose {
        let ml = left.rotation();
        let mr = self.rotation() * ml;
        let cr = left.centre_vec() + ml.transpose() * Vector3::from(self.base);
        Pose::from_rotation(&mr, [cr[0], cr[1], cr[2]])
    }
}

/// The calibration's precision as its maker states it (standard deviations): the
/// prior of the calibration test and of the rig estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPrecision {
    /// Principal point, pixels (each coordinate, each camera).
    pub principal_point_px: f64,
    /// Focal length, relative (0.001 is 0.1 %).
    pub focal: f64,
    /// Relative angles of the rig, radians.
    pub angles_rad: f64,
    /// Base vector components, metres.
    pub base_m: f64,
}

impl CalibrationPrecision {
    /// What a calibration that does not state its precision is taken to have: loose
    /// enough that a pixel of principal-point error, a few tenths of a percent of focal
    /// length and a few hundredths of a degree of relative rotation can be corrected.
    pub const UNSTATED: CalibrationPrecision = CalibrationPrecision {
        principal_point_px: 2.0,
        focal: 0.01,
        angles_rad: 1e-3,
        base_m: 1e-3,
    };

    pub fn valid(&self) -> bool {
        [
            self.principal_point_px,
            self.focal,
            self.angles_rad,
            self.base_m,
        ]
        .iter()
        .all(|v| *v > 0.0 && v.is_finite())
    }
}

impl Default for CalibrationPrecision {
    fn default() -> Self {
        Self::UNSTATED
    }
}

/// `F = diag(1, -1, -1)` maps camera axes (x right, y up, z back) to KITTI's
/// (x right, y down, z forward).
fn flip() -> Matrix3<f64> {
    Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
}

/// KITTI pose (3x4, row-major) of `pose` in the left camera frame of the first
/// epoch `origin`: `R = F M0 Mk^T F`, `t = F M0 (Ck - C0)`.
pub fn kitti_from_pose(origin: &Pose, pose: &Pose) -> [[f64; 4]; 3] {
    let f = flip();
    let m0 = origin.rotation();
    let r = f * m0 * pose.rotation().transpose() * f;
    let t = f * m0 * (pose.centre_vec() - origin.centre_vec());
    let mut out = [[0.0; 4]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for j in 0..3 {
            row[j] = r[(i, j)];
        }
        row[3] = t[i];
    }
    out
}

/// Inverse of [`kitti_from_pose`]: the pose whose KITTI matrix relative to `origin` is `kitti`.
pub fn pose_from_kitti(origin: &Pose, kitti: &[[f64; 4]; 3]) -> Pose {
    let f = flip();
    let m0 = origin.rotation();
    let r = Matrix3::from_fn(|i, j| kitti[i][j]);
    let t = Vector3::new(kitti[0][3], kitti[1][3], kitti[2][3]);
    // Mk^T = M0^T F R F  =>  Mk = F R^T F M0 ;  Ck = C0 + M0^T F t.
    let mk = f * r.transpose() * f * m0;
    let ck = origin.centre_vec() + m0.transpose() * (f * t);
    Pose::from_rotation(&mk, [ck[0], ck[1], ck[2]])
}

#[cfg(test)]
mod tests;
