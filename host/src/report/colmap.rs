//! The run as a COLMAP text model (`cameras.txt`, `images.txt`, `points3D.txt`), which
//! COLMAP, pycolmap and the tools built on them read.
//!
//! COLMAP's cameras look along +z with y down (OpenCV), its poses map the world into
//! the camera (`x_cam = R X + t`, `R` as the quaternion `qw qx qy qz`), and its pixel
//! origin is the corner of the top-left pixel. The photogrammetric camera looks along
//! -z with y up, its rotation `M` maps the object frame into it, and the reports' pixel
//! origin is the centre of the top-left pixel. So `R = diag(1, -1, -1) M`,
//! `t = -R C`, and 0.5 px is added to every pixel coordinate.
//!
//! The cameras are `PINHOLE` (`fx fy cx cy`): the photogrammetric lens model (radial and
//! decentering corrections of the measured coordinates) has no exact counterpart among
//! COLMAP's distortion models, so the image points are written corrected, where a
//! distortion-free camera with the same interior orientation would measure them. For
//! a rig without distortion (KITTI, the rendered streets) they are the measured pixels.
use super::fixed::Fixed;
use super::records::TiePoint;
use anyhow::{Context, Result};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use phototraverse_core::camera::{DistortionModel, Interior, Pose, Rig};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// Added to the reports' pixel coordinates (centre of the top-left pixel = 0) to give
/// COLMAP's (its corner = 0).
pub(super) const PIXEL_ORIGIN: f64 = 0.5;

/// COLMAP's world-to-camera rotation and translation: `x_cam = R X + t`.
type WorldToCamera = (Matrix3<f64>, Vector3<f64>);

/// COLMAP camera ids of the left and right cameras.
const CAMERA_IDS: [u32; 2] = [1, 2];

/// An image of the model.
#[derive(Debug, Clone)]
pub struct ModelImage {
    /// COLMAP image id (unique, > 0).
    pub id: u32,
    /// 0 = left, 1 = right.
    pub camera: u8,
    /// The file, relative to the image root (the dataset directory).
    pub name: String,
    pub pose: Pose,
}

/// A point's track in the model: (image id, index among the image's points), with the
/// mean reprojection error over it, pixels.
struct Track<'a> {
    point: &'a TiePoint,
    elements: Vec<(u32, usize)>,
    mean_error_px: f64,
}

/// What [`write_colmap`] wrote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColmapSummary {
    pub images: usize,
    pub points: usize,
    pub observations: usize,
    /// RMS reprojection error of the written model, pixels.
    pub rms_reprojection_px: f64,
}

/// A `PINHOLE` camera: focal lengths and principal point in COLMAP pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Pinhole {
    /// The distortion-free camera of `interior`.
    pub fn of(interior: &Interior) -> Pinhole {
        let [cx, cy] = ideal(interior).photo_to_pixel(
            interior.principal_point_mm[0],
            interior.principal_point_mm[1],
        );
        Pinhole {
            fx: interior.focal_mm / interior.pixel_size_mm[0],
            fy: interior.focal_mm / interior.pixel_size_mm[1],
            cx: cx + PIXEL_ORIGIN,
            cy: cy + PIXEL_ORIGIN,
        }
    }

    /// COLMAP's projection of a point in the camera frame; `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<[f64; 2]> {
        (p.z > 0.0).then(|| [self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy])
    }
}

/// `interior` without its lens distortion.
fn ideal(interior: &Interior) -> Interior {
    Interior {
        radial: [0.0; 3],
        decentering: [0.0; 2],
        distortion_model: DistortionModel::Correction,
        ..*interior
    }
}

/// Where the distortion-free camera measures what `interior` measured at pixel
/// `(col, row)` (reports' convention), in COLMAP pixels.
pub fn corrected_pixel(interior: &Interior, col: f64, row: f64) -> [f64; 2] {
    let [xc, yc] = interior.pixel_to_corrected(col, row);
    let pp = interior.principal_point_mm;
    let [c, r] = ideal(interior).photo_to_pixel(xc + pp[0], yc + pp[1]);
    [c + PIXEL_ORIGIN, r + PIXEL_ORIGIN]
}

/// COLMAP's world-to-camera rotation and translation of a photogrammetric pose.
pub fn world_to_camera(pose: &Pose) -> WorldToCamera {
    let flip = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
    let r = flip * pose.rotation();
    let t = -(r * Vector3::from(pose.centre));
    (r, t)
}

/// Writes the model of `images` and `points` (measurements keyed by epoch and camera,
/// the image's id `image_id(epoch, camera)`) into `dir`.
pub fn write_colmap(
    dir: &Path,
    rig: &Rig,
    images: &[ModelImage],
    points: &[TiePoint],
    image_id: impl Fn(usize, u8) -> u32,
) -> Result<ColmapSummary> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let interiors = [rig.left, rig.right];
    let pinholes = interiors.map(|i| Pinhole::of(&i));
    // Each image's camera and world-to-camera transform, by id.
    let by_id: BTreeMap<u32, (usize, WorldToCamera)> = images
        .iter()
        .map(|i| (i.id, (i.camera as usize, world_to_camera(&i.pose))))
        .collect();
    // Each image's points (x, y, point id) in order; each point's track (image, index).
    let mut image_points: BTreeMap<u32, Vec<([f64; 2], u32)>> = BTreeMap::new();
    let mut tracks: Vec<Track> = Vec::new();
    let (mut sum_sq, mut observations) = (0.0, 0usize);
    for p in points {
        let (mut track, mut err_sum) = (Vec::new(), 0.0);
        for m in &p.measurements {
            let id = image_id(m.epoch, m.camera);
            let Some(&(camera, (r, t))) = by_id.get(&id) else {
                continue;
            };
            let xy = corrected_pixel(&interiors[camera], m.col, m.row);
            let Some(uv) = pinholes[camera].project(&(r * Vector3::from(p.xyz) + t)) else {
                continue;
            };
            let e2 = (uv[0] - xy[0]).powi(2) + (uv[1] - xy[1]).powi(2);
            let list = image_points.entry(id).or_default();
            track.push((id, list.len()));
            list.push((xy, p.id));
            err_sum += e2.sqrt();
            sum_sq += e2;
            observations += 1;
        }
        if !track.is_empty() {
            tracks.push(Track {
                point: p,
                mean_error_px: err_sum / track.len() as f64,
                elements: track,
            });
        }
    }
    write_cameras(&dir.join("cameras.txt"), &interiors, &pinholes)?;
    write_images(&dir.join("images.txt"), images, &image_points)?;
    write_points(&dir.join("points3D.txt"), &tracks)?;
    Ok(ColmapSummary {
        images: images.len(),
        points: tracks.len(),
        observations,
        rms_reprojection_px: if observations > 0 {
            (sum_sq / observations as f64).sqrt()
        } else {
            0.0
        },
    })
}

fn create(path: &Path) -> Result<std::io::BufWriter<std::fs::File>> {
    let f =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    Ok(std::io::BufWriter::new(f))
}

fn write_cameras(path: &Path, interiors: &[Interior; 2], pinholes: &[Pinhole; 2]) -> Result<()> {
    let mut w = create(path)?;
    writeln!(w, "# Camera list with one line of data per camera:")?;
    writeln!(w, "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]")?;
    writeln!(w, "# Number of cameras: 2 (the rig's left and right)")?;
    for ((id, interior), p) in CAMERA_IDS.iter().zip(interiors).zip(pinholes) {
        writeln!(
            w,
            "{id} PINHOLE {} {} {:.9} {:.9} {:.9} {:.9}",
            interior.width_px, interior.height_px, p.fx, p.fy, p.cx, p.cy
        )?;
    }
    w.flush()?;
    Ok(())
}

fn write_images(
    path: &Path,
    images: &[ModelImage],
    points: &BTreeMap<u32, Vec<([f64; 2], u32)>>,
) -> Result<()> {
    let mut w = create(path)?;
    writeln!(w, "# Image list with two lines of data per image:")?;
    writeln!(
        w,
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME"
    )?;
    writeln!(w, "#   POINTS2D[] as (X, Y, POINT3D_ID)")?;
    writeln!(w, "# Number of images: {}", images.len())?;
    for image in images {
        let (r, t) = world_to_camera(&image.pose);
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
        writeln!(
            w,
            "{} {:.12} {:.12} {:.12} {:.12} {:.9} {:.9} {:.9} {} {}",
            image.id,
            q.w,
            q.i,
            q.j,
            q.k,
            t.x,
            t.y,
            t.z,
            CAMERA_IDS[image.camera as usize],
            image.name
        )?;
        let list = points.get(&image.id).map_or(&[][..], Vec::as_slice);
        for (k, (xy, id)) in list.iter().enumerate() {
            let sep = if k == 0 { "" } else { " " };
            write!(w, "{sep}{} {} {id}", Fixed::<4>(xy[0]), Fixed::<4>(xy[1]))?;
        }
        writeln!(w)?;
    }
    w.flush()?;
    Ok(())
}

fn write_points(path: &Path, tracks: &[Track]) -> Result<()> {
    let mut w = create(path)?;
    writeln!(w, "# 3D point list with one line of data per point:")?;
    writeln!(
        w,
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"
    )?;
    writeln!(w, "# Number of points: {}", tracks.len())?;
    for Track {
        point: p,
        elements,
        mean_error_px: error,
    } in tracks
    {
        let t: Vec<String> = elements.iter().map(|(i, k)| format!("{i} {k}")).collect();
        writeln!(
            w,
            "{} {:.6} {:.6} {:.6} 128 128 128 {:.6} {}",
            p.id,
            p.xyz[0],
            p.xyz[1],
            p.xyz[2],
            error,
            t.join(" ")
        )?;
    }
    w.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::records::ImageMeasurement;
    use phototraverse_core::camera::project_to_pixel;

    /// The test camera with anisotropic pixels, in a converging rig.
    fn rig() -> Rig {
        let camera = Interior {
            pixel_size_mm: [0.005, 0.0052],
            ..phototraverse_core::testkit::test_camera()
        };
        Rig {
            left: camera,
            right: camera,
            relative_angles: [0.002, -0.01, 0.003],
            base_m: [0.4, 0.01, -0.02],
        }
    }

    #[test]
    fn the_model_projects_where_the_photogrammetric_camera_measured() {
        let rig = rig();
        let left = Pose::from_degrees(92.0, 1.0, -2.0, [1.0, 2.0, 1.5]);
        let poses = [left, rig.right_pose(&left)];
        let images: Vec<ModelImage> = (0..2)
            .map(|c| ModelImage {
                id: c as u32 + 1,
                camera: c as u8,
                name: format!("cam{c}.png"),
                pose: poses[c],
            })
            .collect();
        // Points ahead of the rig, measured through the full model (distortion included).
        let points: Vec<TiePoint> = (0..20)
            .map(|k| {
                let xyz = [-3.0 + 0.3 * k as f64, 12.0 + k as f64, 0.5 - 0.1 * k as f64];
                let measurements = (0..2)
                    .map(|c| {
                        let interior = if c == 0 { &rig.left } else { &rig.right };
                        let [col, row] = project_to_pixel(&poses[c], interior, &xyz).unwrap();
                        ImageMeasurement {
                            epoch: 0,
                            camera: c as u8,
                            col,
                            row,
                        }
                    })
                    .collect();
                TiePoint {
                    id: k + 10,
                    xyz,
                    sigma: None,
                    measurements,
                }
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let s = write_colmap(dir.path(), &rig, &images, &points, |_, c| c as u32 + 1).unwrap();
        assert_eq!((s.images, s.points, s.observations), (2, 20, 40));
        assert!(s.rms_reprojection_px < 1e-6, "{s:?}");
        // Read back as COLMAP would: the first image's pose and points, the left camera.
        let text = std::fs::read_to_string(dir.path().join("images.txt")).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let head: Vec<f64> = lines
            .next()
            .unwrap()
            .split(' ')
            .take(8)
            .map(|v| v.parse().unwrap())
            .collect();
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            head[1], head[2], head[3], head[4],
        ));
        let t = Vector3::new(head[5], head[6], head[7]);
        let cams = std::fs::read_to_string(dir.path().join("cameras.txt")).unwrap();
        let p: Vec<f64> = cams
            .lines()
            .find(|l| l.starts_with("1 PINHOLE"))
            .unwrap()
            .split(' ')
            .skip(4)
            .map(|v| v.parse().unwrap())
            .collect();
        let pinhole = Pinhole {
            fx: p[0],
            fy: p[1],
            cx: p[2],
            cy: p[3],
        };
        let obs: Vec<f64> = lines
            .next()
            .unwrap()
            .split(' ')
            .map(|v| v.parse().unwrap())
            .collect();
        for (k, chunk) in obs.chunks(3).enumerate() {
            let point = &points[k];
            assert_eq!(chunk[2] as u32, point.id);
            let uv = pinhole
                .project(&(q * Vector3::from(point.xyz) + t))
                .unwrap();
            assert!(
                (uv[0] - chunk[0]).abs() < 1e-3 && (uv[1] - chunk[1]).abs() < 1e-3,
                "{uv:?} {chunk:?}"
            );
        }
    }

    #[test]
    fn without_distortion_the_points_are_the_measured_pixels_shifted_by_half_a_pixel() {
        let mut camera = rig().left;
        camera.radial = [0.0; 3];
        camera.decentering = [0.0; 2];
        let [c, r] = corrected_pixel(&camera, 100.25, 50.75);
        assert!(
            (c - 100.75).abs() < 1e-9 && (r - 51.25).abs() < 1e-9,
            "{c} {r}"
        );
    }
}
