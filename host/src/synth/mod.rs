//! Synthetic street sequences with ground truth.
//!
//! A street corridor (ground with markings, facades with gaps, parked cars,
//! poles, sky; [`scene`]) is built along a centre line ([`path`]) and ray cast
//! ([`render`]) by the stereo rig of a named scene ([`scenes`]) along a smooth
//! trajectory. [`generate`] writes the dataset in the KITTI or rig.toml layout
//! with `gt_poses.txt`, optional depth maps and realistic imperfections
//! ([`realism`]). Everything is deterministic for a seed.
pub mod aiding;
pub mod geometry;
pub mod material;
pub mod noise;
pub mod path;
pub mod photo;
pub mod realism;
pub mod render;
pub mod scene;
pub mod scenes;
pub mod writer;

use crate::dataset::{kitti, rigfile, GT_FILE, TIMES_FILE};
use crate::poses::{write_poses, KittiPose};
use anyhow::{bail, Context};
use phototraverse_core::camera::{kitti_from_pose, Pose, Rig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realism::{develop, gaussian_blur, CalibError, Imperfections};
use render::{render, RenderSettings};
pub use scenes::{plan, LayoutChoice, ScenePlan, SCENES};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// What to synthesize.
#[derive(Debug, Clone)]
pub struct SynthOptions {
    pub scene: String,
    pub out: PathBuf,
    pub frames: Option<usize>,
    pub seed: u64,
    pub layout: Option<LayoutChoice>,
    pub depth: bool,
    pub calib_error: CalibError,
    pub imperfections: Imperfections,
    pub jpeg_quality: Option<u8>,
    pub edge_ss: u32,
    pub progress: bool,
    /// Image size `(width, height)` instead of the scene's: the same sensor and field of
    /// view sampled by other pixels (see [`resample`]).
    pub size: Option<(u32, u32)>,
    /// Render with these cameras instead of the scene's (a user's rig, e.g. from
    /// `rig import`); the scene's path and datum stay.
    pub rig: Option<Rig>,
    /// Texture the facades with these photographs (files, or directories of them;
    /// [`photo`]); none: the procedural facades.
    pub photo_textures: Vec<PathBuf>,
    /// Simulated GNSS and odometer ([`aiding`]); the default writes neither.
    pub aiding: aiding::AidingOptions,
}

impl SynthOptions {
    pub fn new(scene: &str, out: PathBuf) -> Self {
        SynthOptions {
            scene: scene.to_string(),
            out,
            frames: None,
            seed: 1,
            layout: None,
            depth: false,
            calib_error: CalibError::default(),
            imperfections: Imperfections::default(),
            jpeg_quality: None,
            edge_ss: RenderSettings::default().edge_ss,
            progress: false,
            size: None,
            rig: None,
            photo_textures: Vec::new(),
            aiding: aiding::AidingOptions::default(),
        }
    }
}

/// What was written (also `DIR/synth.json`).
#[derive(Debug, Clone, Serialize)]
pub struct SynthSummary {
    pub scene: String,
    pub frames: usize,
    pub seed: u64,
    pub layout: String,
    pub width: u32,
    pub height: u32,
    pub path_length_m: f64,
    /// Mean and maximum ray-casting time of one image, ms (without writing).
    pub render_ms_mean: f64,
    pub render_ms_max: f64,
    /// Process CPU time spent rendering one image, ms (Linux `/proc/self/stat`;
    /// None elsewhere). On an idle machine the wall time is about this divided by `threads`.
    pub render_cpu_ms_mean: Option<f64>,
    /// Share of pixels supersampled as silhouettes.
    pub edge_fraction: f64,
    /// Share of an image's pixels that see moving objects (vehicles of `traffic` and
    /// `hard`): largest over the images, and mean.
    pub moving_fraction_max: f64,
    pub moving_fraction_mean: f64,
    pub threads: usize,
}

/// Process CPU time (user + system) in ms, from `/proc/self/stat` (Linux).
pub fn process_cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name in parentheses: utime and stime are the 12th and 13th.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    // USER_HZ is 100 on every Linux configuration in use.
    Some((utime + stime) * 10.0)
}

fn mix(seed: u64, k: u64, cam: u64) -> u64 {
    seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
        ^ k.wrapping_mul(0xbf58_476d_1ce4_e5b9)
        ^ cam.wrapping_mul(0x94d0_49bb_1331_11eb)
}

/// `cam` with `w` x `h` pixels on the same sensor: the pixel size scales so the sensor
/// (and so the field of view, the principal point and the distortion, all in mm) stays.
pub fn resample(
    cam: &phototraverse_core::camera::Interior,
    w: u32,
    h: u32,
) -> anyhow::Result<phototraverse_core::camera::Interior> {
    anyhow::ensure!(
        (16..=8192).contains(&w) && (16..=8192).contains(&h),
        "image size {w}x{h} out of 16..=8192"
    );
    let sx = cam.width_px as f64 / w as f64;
    let sy = cam.height_px as f64 / h as f64;
    Ok(phototraverse_core::camera::Interior {
        width_px: w,
        height_px: h,
        pixel_size_mm: [cam.pixel_size_mm[0] * sx, cam.pixel_size_mm[1] * sy],
        ..*cam
    })
}

/// Renders and writes the dataset.
pub fn generate(opts: &SynthOptions) -> anyhow::Result<SynthSummary> {
    let mut plan = plan(&opts.scene, opts.frames, opts.seed).map_err(anyhow::Error::msg)?;
    if let Some(rig) = opts.rig {
        plan.rig = rig;
        // A user's cameras have their lenses and relative orientation, which only
        // the rig layout can state.
        plan.layout = LayoutChoice::Rig;
    }
    if let Some((w, h)) = opts.size {
        plan.rig.left = resample(&plan.rig.left, w, h)?;
        plan.rig.right = resample(&plan.rig.right, w, h)?;
    }
    if !opts.photo_textures.is_empty() {
        plan.scene.photos = Some(std::sync::Arc::new(photo::Photos::load(
            &opts.photo_textures,
        )?));
    }
    let layout = opts.layout.unwrap_or(plan.layout);
    let truth = plan.rig;
    let mut calib_rng = ChaCha8Rng::seed_from_u64(mix(opts.seed, u64::MAX, 7));
    let mut written = opts.calib_error.perturb(&truth, &mut calib_rng);
    let mut render_rig = truth;
    if layout == LayoutChoice::Kitti {
        if !truth.left.is_distortion_free()
            || !truth.right.is_distortion_free()
            || truth.relative_angles != [0.0; 3]
            || truth.base_m[1..] != [0.0; 2]
        {
            bail!("scene `{}` has lens distortion or a non-rectified rig, which KITTI's calib.txt cannot express: use --layout rig", plan.name);
        }
        // KITTI is rectified: the relative-rotation residual goes into the rendering rig instead.
        for i in 0..3 {
            render_rig.relative_angles[i] -= written.relative_angles[i];
        }
        written.relative_angles = [0.0; 3];
    }

    let out = &opts.out;
    let (dir_l, dir_r) = match layout {
        LayoutChoice::Kitti => ("image_0", "image_1"),
        LayoutChoice::Rig => ("left", "right"),
    };
    for d in [dir_l, dir_r] {
        std::fs::create_dir_all(out.join(d))
            .with_context(|| format!("{}: cannot create", out.join(d).display()))?;
    }
    if opts.depth {
        for d in ["depth_0", "depth_1"] {
            std::fs::create_dir_all(out.join(d))?;
        }
    }
    let poses: Vec<Pose> = (0..plan.frames).map(|k| plan.left_pose(k as f64)).collect();
    let origin = poses[0];
    match layout {
        LayoutChoice::Kitti => std::fs::write(out.join("calib.txt"), kitti::calib_text(&written))?,
        LayoutChoice::Rig => rigfile::write_rig(&out.join("rig.toml"), &written, &origin)?,
    }
    // The rig that really rendered the images, for tests and calibration studies.
    rigfile::write_rig(&out.join("truth_rig.toml"), &render_rig, &origin)?;
    let gt: Vec<KittiPose> = poses.iter().map(|p| kitti_from_pose(&origin, p)).collect();
    write_poses(&out.join(GT_FILE), &gt)?;
    let times: String = (0..plan.frames)
        .map(|k| format!("{:.6}\n", k as f64 * plan.dt))
        .collect();
    std::fs::write(out.join(TIMES_FILE), times)?;
    let datum = match layout {
        LayoutChoice::Kitti => rigfile::default_datum(),
        LayoutChoice::Rig => origin,
    };
    aiding::write_aiding(out, &plan, (&datum, &origin), &opts.aiding, opts.seed)?;

    let settings = RenderSettings {
        edge_ss: opts.edge_ss,
        depth: opts.depth,
        ..Default::default()
    };
    let ext = if opts.jpeg_quality.is_some() {
        "jpg"
    } else {
        "png"
    };
    let bar = if opts.progress {
        let bar = indicatif::ProgressBar::new(plan.frames as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} {elapsed}<{eta}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_message(format!("synth {}", plan.name));
        bar
    } else {
        indicatif::ProgressBar::hidden()
    };
    let (mut ms_sum, mut ms_max, mut edges, mut images) = (0.0f64, 0.0f64, 0usize, 0usize);
    let (mut moving_sum, mut moving_max) = (0.0f64, 0.0f64);
    let mut cpu_sum: Option<f64> = None;
    let imp = opts.imperfections;
    for (k, left_pose) in poses.iter().enumerate() {
        let right_pose = render_rig.right_pose(left_pose);
        for (cam_index, (cam, pose)) in [
            (&render_rig.left, *left_pose),
            (&render_rig.right, right_pose),
        ]
        .into_iter()
        .enumerate()
        {
            let t0 = Instant::now();
            let cpu0 = process_cpu_ms();
            let (w, h) = (cam.width_px as usize, cam.height_px as usize);
            let (mut radiance, depth, edge_pixels, moving_pixels) = match &plan.hard {
                Some(hard) if hard.subframes > 1 => {
                    // Motion blur: average sub-frames over the exposure; depth from the middle one.
                    let mut acc = vec![0.0f32; w * h];
                    let mut depth = Vec::new();
                    let (mut e, mut moving) = (0, 0);
                    let n = hard.subframes;
                    for j in 0..n {
                        let dk = hard.shutter * (j as f64 / (n - 1) as f64 - 0.5);
                        let kk = k as f64 + dk;
                        let lp = plan.left_pose(kk);
                        let p = if cam_index == 0 {
                            lp
                        } else {
                            render_rig.right_pose(&lp)
                        };
                        let mid = j == n / 2;
                        let s = RenderSettings {
                            depth: settings.depth && mid,
                            ..settings
                        };
                        let img = render(&plan.scene, &plan.moving(kk), cam, &p, &s);
                        for (a, v) in acc.iter_mut().zip(&img.radiance) {
                            *a += v / n as f32;
                        }
                        if mid {
                            depth = img.depth;
                            e = img.edge_pixels;
                            moving = img.moving_pixels;
                        }
                    }
                    (acc, depth, e, moving)
                }
                _ => {
                    let img = render(&plan.scene, &plan.moving(k as f64), cam, &pose, &settings);
                    (img.radiance, img.depth, img.edge_pixels, img.moving_pixels)
                }
            };
            let moving = moving_pixels as f64 / (w * h) as f64;
            moving_sum += moving;
            moving_max = moving_max.max(moving);
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            if let (Some(a), Some(b)) = (cpu0, process_cpu_ms()) {
                cpu_sum = Some(cpu_sum.unwrap_or(0.0) + (b - a));
            }
            ms_sum += ms;
            ms_max = ms_max.max(ms);
            edges += edge_pixels;
            images += 1;

            let mut rng = ChaCha8Rng::seed_from_u64(mix(opts.seed, k as u64, cam_index as u64));
            gaussian_blur(&mut radiance, w, h, imp.blur_px);
            let flicker = if imp.flicker > 0.0 {
                1.0 + rng.gen_range(-imp.flicker..=imp.flicker)
            } else {
                1.0
            };
            let gain = flicker * plan.exposure(k);
            let pixels = develop(&radiance, w, h, gain, &imp, &mut rng);
            let name = if plan.seed_names {
                format!(
                    "{}{:04}.{ext}",
                    if cam_index == 0 { 'E' } else { 'D' },
                    k + 1
                )
            } else {
                format!("{k:06}.{ext}")
            };
            let dir = if cam_index == 0 { dir_l } else { dir_r };
            writer::write_gray(
                &out.join(dir).join(name),
                &pixels,
                w as u32,
                h as u32,
                opts.jpeg_quality,
            )?;
            if opts.depth {
                writer::write_pfm(
                    &out.join(format!("depth_{cam_index}"))
                        .join(format!("{k:06}.pfm")),
                    &depth,
                    w,
                    h,
                )?;
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let (w, h) = (truth.left.width_px, truth.left.height_px);
    let summary = SynthSummary {
        scene: plan.name.to_string(),
        frames: plan.frames,
        seed: opts.seed,
        layout: format!("{layout:?}").to_lowercase(),
        width: w,
        height: h,
        path_length_m: plan.stations[plan.frames - 1] - plan.stations[0],
        render_ms_mean: ms_sum / images.max(1) as f64,
        render_ms_max: ms_max,
        render_cpu_ms_mean: cpu_sum.map(|c| c / images.max(1) as f64),
        edge_fraction: edges as f64 / (images.max(1) as f64 * w as f64 * h as f64),
        moving_fraction_max: moving_max,
        moving_fraction_mean: moving_sum / images.max(1) as f64,
        threads: rayon::current_num_threads(),
    };
    std::fs::write(
        out.join("synth.json"),
        serde_json::to_string_pretty(&summary)? + "\n",
    )?;
    Ok(summary)
}
