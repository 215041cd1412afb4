//! The renderer's geometry: small discs at known 3D points render within
//! 0.1 px of their collinearity projection, with and without distortion; and
//! depth maps give true correspondences between the two cameras.
use phototraverse_core::camera::{project_to_pixel, Interior, Pose, Rig};
use phototraverse_host::synth::geometry::{Shape, V3};
use phototraverse_host::synth::material::Material;
use phototraverse_host::synth::render::{render, RenderSettings};
use phototraverse_host::synth::scene::{Primitive, Scene};

/// Seed 000 Quadro 1, left camera.
fn seed_left() -> Interior {
    phototraverse_host::synth::scenes::seed000_rig().left
}

/// Renders discs at a grid of known points and returns the largest distance
/// between a disc's intensity centroid and the projection of its centre.
fn max_disc_error(cam: &Interior, pose: &Pose, radius_px: f64) -> (f64, usize) {
    let f_px = cam.focal_mm / cam.pixel_size_mm[0];
    let (w, h) = (cam.width_px as f64, cam.height_px as f64);
    let mut scene = Scene::empty(0.0);
    let mut targets = Vec::new();
    let m = pose.rotation();
    let c = pose.centre_vec();
    // A 7 x 5 grid over the format (to the corners, where distortion is largest),
    // at depths 6..30 m, centres off the pixel grid.
    for i in 0..7 {
        for j in 0..5 {
            let depth = 6.0 + ((i * 5 + j) % 7) as f64 * 4.0;
            let col = 20.0 + (w - 40.0) * i as f64 / 6.0 + 0.37 * j as f64;
            let row = 20.0 + (h - 40.0) * j as f64 / 4.0 + 0.21 * i as f64;
            let [xc, yc] = cam.pixel_to_corrected(col, row);
            // The point on that ray at the given depth.
            let dir = m.transpose() * V3::new(xc, yc, -cam.focal_mm) / cam.focal_mm;
            let p = c + dir * depth;
            let radius = radius_px * depth / f_px;
            let normal = (c - p).normalize();
            scene.prims.push(Primitive {
                shape: Shape::Disc {
                    centre: p,
                    normal,
                    radius,
                },
                material: Material::Emissive { value: 1.0 },
                flat: false,
                group: targets.len() as u32,
            });
            targets.push([p[0], p[1], p[2]]);
        }
    }
    let img = render(&scene, &[], cam, pose, &RenderSettings::default());
    let mut worst: f64 = 0.0;
    for p in &targets {
        let [pc, pr] = project_to_pixel(pose, cam, p).unwrap();
        let win = (radius_px * 1.6 + 3.0).ceil() as i64;
        let (mut s, mut sc, mut sr) = (0.0, 0.0, 0.0);
        for r in (pr.round() as i64 - win)..=(pr.round() as i64 + win) {
            for c in (pc.round() as i64 - win)..=(pc.round() as i64 + win) {
                let v = img.radiance[r as usize * img.width + c as usize] as f64;
                s += v;
                sc += v * c as f64;
                sr += v * r as f64;
            }
        }
        assert!(s > 0.0, "disc at {p:?} not rendered");
        let e = ((sc / s - pc).powi(2) + (sr / s - pr).powi(2)).sqrt();
        worst = worst.max(e);
    }
    (worst, targets.len())
}

#[test]
fn discs_render_at_their_projection_without_distortion() {
    // 640 x 480 pixels, f = 500 px.
    let cam = Interior::pinhole_px(640, 480, 500.0);
    let pose = Pose::from_degrees(91.3, -2.0, 4.0, [1.0, -3.0, 1.6]);
    let (err, n) = max_disc_error(&cam, &pose, 3.0);
    println!("pinhole 640x480: max centroid error {err:.4} px over {n} discs");
    assert!(err < 0.1, "{err}");
}

#[test]
fn discs_render_at_their_projection_with_distortion() {
    let cam = seed_left();
    let pose = Pose::from_degrees(89.0, 1.5, -3.0, [-2.0, 5.0, 1.7]);
    let (err, n) = max_disc_error(&cam, &pose, 3.0);
    println!("seed 000 lens 576x384: max centroid error {err:.4} px over {n} discs");
    assert!(err < 0.1, "{err}");
    // The distortion is not negligible here: ignoring it would miss by more than a pixel.
    let mut pinhole = cam;
    pinhole.radial = [0.0; 3];
    pinhole.decentering = [0.0; 2];
    let p = [-2.0 + 8.0, 5.0 + 20.0, 1.7 + 4.0];
    let a = project_to_pixel(&pose, &cam, &p).unwrap();
    let b = project_to_pixel(&pose, &pinhole, &p).unwrap();
    assert!(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt() > 0.5);
}

#[test]
fn depth_maps_give_true_stereo_correspondences() {
    use phototraverse_host::synth::plan;
    let plan = plan("seed2014", Some(1), 3).unwrap();
    let rig: Rig = plan.rig;
    let left_pose = plan.left_pose(0.0);
    let right_pose = rig.right_pose(&left_pose);
    let s = RenderSettings::default();
    let l = render(&plan.scene, &[], &rig.left, &left_pose, &s);
    let r = render(&plan.scene, &[], &rig.right, &right_pose, &s);
    let (m, c) = (left_pose.rotation(), left_pose.centre_vec());
    let (mut diffs, mut shifted) = (Vec::new(), Vec::new());
    for row in (10..l.height - 10).step_by(7) {
        for col in (10..l.width - 10).step_by(7) {
            let z = l.depth[row * l.width + col] as f64;
            if !z.is_finite() {
                continue;
            }
            let [xc, yc] = rig.left.pixel_to_corrected(col as f64, row as f64);
            let p =
                c + m.transpose() * V3::new(xc, yc, -rig.left.focal_mm) * (z / rig.left.focal_mm);
            let Ok([pc, pr]) = project_to_pixel(&right_pose, &rig.right, &[p[0], p[1], p[2]])
            else {
                continue;
            };
            let (ic, ir) = (pc.round() as isize, pr.round() as isize);
            if ic < 1 || ir < 1 || ic as usize >= r.width - 1 || ir as usize >= r.height - 1 {
                continue;
            }
            let vr = r.radiance[ir as usize * r.width + ic as usize];
            let vs = r.radiance[ir as usize * r.width + (ic as usize + 5).min(r.width - 1)];
            let vl = l.radiance[row * l.width + col];
            diffs.push((vl - vr).abs());
            shifted.push((vl - vs).abs());
        }
    }
    diffs.sort_by(f32::total_cmp);
    shifted.sort_by(f32::total_cmp);
    let (med, med_shift) = (diffs[diffs.len() / 2], shifted[shifted.len() / 2]);
    println!(
        "{} correspondences: median |L - R| {med:.4}, 5 px off {med_shift:.4}",
        diffs.len()
    );
    assert!(diffs.len() > 2000);
    // Rounding to the nearest pixel leaves a little texture difference; a wrong match leaves much more.
    assert!(med < 0.02 && med < med_shift / 3.0, "{med} vs {med_shift}");
}

/// `synth --size WxH` (`synth::resample`) samples the same sensor with other pixels:
/// the field of view, the principal point and the distortion (all in mm) stay, so a
/// point lands at the same place on the sensor, i.e. at the scaled pixel position, and
/// the renderer still draws it there (seed 000's lens at 640x480 and 320x240).
#[test]
fn a_resampled_lens_keeps_its_field_of_view_and_distortion() {
    use phototraverse_host::synth::resample;
    let cam = seed_left();
    let pose = Pose::from_degrees(89.0, 1.5, -3.0, [-2.0, 5.0, 1.7]);
    for (w, h) in [(640u32, 480u32), (320, 240)] {
        let small = resample(&cam, w, h).unwrap();
        let (sx, sy) = (
            w as f64 / cam.width_px as f64,
            h as f64 / cam.height_px as f64,
        );
        // The image corners see the same directions.
        let a = cam.pixel_to_corrected(-0.5, -0.5);
        let b = small.pixel_to_corrected(-0.5, -0.5);
        assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12);
        for i in 0..20 {
            let p = [
                -2.0 + 5.0 * (i as f64 * 0.7).sin(),
                5.0 + 8.0 + i as f64,
                1.7 + 2.0 * (i as f64 * 1.3).cos(),
            ];
            let [c, r] = project_to_pixel(&pose, &cam, &p).unwrap();
            let [c2, r2] = project_to_pixel(&pose, &small, &p).unwrap();
            assert!(
                (c2 - ((c + 0.5) * sx - 0.5)).abs() < 1e-6
                    && (r2 - ((r + 0.5) * sy - 0.5)).abs() < 1e-6,
                "{w}x{h}: ({c}, {r}) -> ({c2}, {r2})"
            );
        }
        let (err, n) = max_disc_error(&small, &pose, 2.5);
        println!("seed 000 lens at {w}x{h}: max centroid error {err:.4} px over {n} discs");
        assert!(err < 0.1, "{w}x{h}: {err}");
    }
}
