//! Linear intersection of two or more rays, seed 000 §5.4 ("MIFL").
//!
//! Each ray (pose, focal length, corrected photo-coordinates) gives two linear
//! equations in the object point by clearing the collinearity denominators
//! (seed eq. 40, written with `M`'s rows):
//! `(xc m3 + f m1) . P = (xc m3 + f m1) . C`, `(yc m3 + f m2) . P = (yc m3 + f m2) . C`.
//! The rows are stacked and solved by least squares with `P = I` (eq. 43).
//! The result is then checked: every ray must see the point in front of its
//! camera, and the largest angle between two rays must exceed a minimum
//! (a point at infinity or a zero base gives parallel rays).

use crate::camera::Pose;
use nalgebra::{Matrix3, Vector3};

/// One image ray: the camera's pose, its focal length and the corrected photo-coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub pose: Pose,
    pub focal_mm: f64,
    pub xy: [f64; 2],
}

/// An intersected point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intersection {
    pub point: [f64; 3],
    /// Largest angle between two of the rays, radians.
    pub max_ray_angle: f64,
}

/// Why an intersection was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntersectError {
    /// Fewer than two rays.
    TooFewRays,
    /// A coordinate or pose is NaN or infinite.
    NotFinite,
    /// Rays (nearly) parallel: the point is at infinity or the base is zero.
    SmallRayAngle,
    /// The normal matrix is singular.
    Singular,
    /// The point lies behind one of the cameras.
    BehindCamera,
}

impl core::fmt::Display for IntersectError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            IntersectError::TooFewRays => "intersection needs at least two rays",
            IntersectError::NotFinite => "ray is not finite",
            IntersectError::SmallRayAngle => {
                "rays are nearly parallel (point at infinity or zero base)"
            }
            IntersectError::Singular => "intersection normal matrix is singular",
            IntersectError::BehindCamera => "intersected point lies behind a camera",
        })
    }
}

/// Direction of a ray in object space (unit vector): `M^T (xc, yc, -f)`.
pub fn ray_direction(ray: &Ray) -> Vector3<f64> {
    let d = ray.pose.rotation().transpose() * Vector3::new(ray.xy[0], ray.xy[1], -ray.focal_mm);
    d / d.norm()
}

/// Intersects `rays`; `min_angle_rad` is the smallest acceptable largest ray angle.
pub fn intersect(rays: &[Ray], min_angle_rad: f64) -> Result<Intersection, IntersectError> {
    if rays.len() < 2 {
        return Err(IntersectError::TooFewRays);
    }
    let mut n = Matrix3::<f64>::zeros();
    let mut t = Vector3::<f64>::zeros();
    for ray in rays {
        let finite = ray
            .pose
            .to_params()
            .iter()
            .chain(ray.xy.iter())
            .all(|v| v.is_finite())
            && ray.focal_mm.is_finite()
            && ray.focal_mm > 0.0;
        if !finite {
            return Err(IntersectError::NotFinite);
        }
        let m = ray.pose.rotation();
        let c = ray.pose.centre_vec();
        let (r1, r2, r3) = (
            m.row(0).transpose(),
            m.row(1).transpose(),
            m.row(2).transpose(),
        );
        // Rows scaled by 1/f so cameras with different focal lengths weigh alike.
        for a in [
            (ray.xy[0] * r3 + ray.focal_mm * r1),
            (ray.xy[1] * r3 + ray.focal_mm * r2),
        ] {
            let a = a / ray.focal_mm;
            n += a * a.transpose();
            t += a * a.dot(&c);
        }
    }
    let max_angle = max_ray_angle(rays);
    if !(max_angle >= min_angle_rad) {
        return Err(IntersectError::SmallRayAngle);
    }
    let chol = n.cholesky().ok_or(IntersectError::Singular)?;
    let p = chol.solve(&t);
    if !p.iter().all(|v| v.is_finite()) {
        return Err(IntersectError::Singular);
    }
    let point = [p[0], p[1], p[2]];
    for ray in rays {
        if !(ray.pose.to_camera(&point)[2] < -crate::camera::MIN_DEPTH) {
            return Err(IntersectError::BehindCamera);
        }
    }
    Ok(Intersection {
        point,
        max_ray_angle: max_angle,
    })
}

/// Largest angle between any two rays, radians.
pub fn max_ray_angle(rays: &[Ray]) -> f64 {
    let mut best = 0.0f64;
    for (i, a) in rays.iter().enumerate() {
        let da = ray_direction(a);
        for b in &rays[i + 1..] {
            let cosang = da.dot(&ray_direction(b)).clamp(-1.0, 1.0);
            best = best.max(libm::acos(cosang));
        }
    }
    best
}
