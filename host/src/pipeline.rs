//! Pipeline settings a user gives in a TOML file (`--config FILE`) and the
//! `Configure` message they become.
use anyhow::{Context, Result};
use phototraverse_core::camera::{CalibrationPrecision, Interior, Pose, Rig};
use phototraverse_core::protocol::messages::{
    AdjustMode, Configure, Pipeline, TraverseSettings, CONFIG_VERSION,
};
use phototraverse_core::traverse::defaults::{
    TRAVERSE_CONTRAST, TRAVERSE_DISPARITY_FRACTION, TRAVERSE_EDGE_RATIO, TRAVERSE_FIXED_EPOCHS,
    TRAVERSE_KEYPOINTS, TRAVERSE_MATCH_RATIO, TRAVERSE_OCTAVES, TRAVERSE_SCALES, TRAVERSE_SIGMA_PX,
    TRAVERSE_TRACKS, TRAVERSE_WINDOW,
};
use phototraverse_core::traverse::TraverseMode;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How the traverse adjusts (`--mode`, `mode = "..."`): see docs/configuration.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Sliding window (3 epochs; 8 with --estimate-rig), robust snooping, base-length and smoothness constraints.
    #[default]
    Window,
    /// Seed 000 (Lemes Neto 2014): two-epoch sequences, base constraints, one re-weighting.
    Seed2014,
    /// Seed 002 (Barbosa 2006): 7 bases together, base-length and velocity constraints.
    Seed2006,
}

impl Mode {
    pub fn core(self) -> TraverseMode {
        match self {
            Mode::Window => TraverseMode::Window,
            Mode::Seed2014 => TraverseMode::Seed2014,
            Mode::Seed2006 => TraverseMode::Seed2006,
        }
    }

    pub fn name(self) -> &'static str {
        self.core().name()
    }

    /// The mode as the Configure message names it.
    pub fn wire(self) -> AdjustMode {
        match self {
            Mode::Window => AdjustMode::Window,
            Mode::Seed2014 => AdjustMode::Seed2014,
            Mode::Seed2006 => AdjustMode::Seed2006,
        }
    }
}

/// The datum in a settings file: the left camera at epoch 0.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatumSettings {
    pub omega_deg: f64,
    pub phi_deg: f64,
    pub kappa_deg: f64,
    pub position_m: [f64; 3],
}

impl DatumSettings {
    pub fn pose(&self) -> Pose {
        Pose::from_degrees(
            self.omega_deg,
            self.phi_deg,
            self.kappa_deg,
            self.position_m,
        )
    }
}

/// Pipeline settings; every key is optional (defaults in brackets).
///
/// ```toml
/// keypoints_per_image = 1000   # features kept per image
/// octaves = 4                  # scale-space octaves
/// scales_per_octave = 3
/// contrast_threshold = 0.015   # DoG contrast, grey levels / 255
/// fine_octave = false          # half-pixel scales too: ~2x keypoints, ~2x SIFT time
/// edge_ratio = 10.0            # principal curvature ratio
/// match_ratio = 0.8            # Lowe's ratio
/// max_disparity_px = 320.0     # rectified rigs: disparity search range (default: half the width)
/// window = 3                   # epochs in the adjustment window
/// track_capacity = 600         # tracks kept at once
/// fixed_epochs = 8             # epochs that left the window whose observations still count
/// mode = "window"              # window, seed2014, seed2006
/// estimate_rig = false         # estimate the rig and the right camera's interior freely
/// check_calibration = true     # test the calibration, correct it where the images call for it
/// sigma_px = 0.5               # a-priori image sigma, pixels
/// # [datum] omega_deg, phi_deg, kappa_deg, position_m (default: the dataset's)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineSettings {
    pub keypoints_per_image: u32,
    pub octaves: u8,
    pub scales_per_octave: u8,
    pub contrast_threshold: f32,
    /// The extractor's fine octave (the scales OpenCV reaches by doubling the image).
    pub fine_octave: bool,
    pub edge_ratio: f32,
    pub match_ratio: f32,
    /// `None`: half the image width.
    pub max_disparity_px: Option<f32>,
    pub window: u16,
    pub track_capacity: u32,
    pub fixed_epochs: u16,
    pub mode: Mode,
    pub estimate_rig: bool,
    /// The calibration check (default on; `false` holds the calibration as given).
    pub check_calibration: bool,
    pub sigma_px: f64,
    /// `None`: the dataset's datum (rig.toml `[datum]`, else omega 90 at the origin).
    pub datum: Option<DatumSettings>,
}

impl Default for PipelineSettings {
    fn default() -> Self {
        PipelineSettings {
            keypoints_per_image: TRAVERSE_KEYPOINTS as u32,
            octaves: TRAVERSE_OCTAVES as u8,
            scales_per_octave: TRAVERSE_SCALES as u8,
            contrast_threshold: TRAVERSE_CONTRAST,
            fine_octave: false,
            edge_ratio: TRAVERSE_EDGE_RATIO,
            match_ratio: TRAVERSE_MATCH_RATIO,
            max_disparity_px: None,
            window: TRAVERSE_WINDOW as u16,
            track_capacity: TRAVERSE_TRACKS as u32,
            fixed_epochs: TRAVERSE_FIXED_EPOCHS as u16,
            mode: Mode::Window,
            estimate_rig: false,
            check_calibration: true,
            sigma_px: TRAVERSE_SIGMA_PX,
            datum: None,
        }
    }
}

impl PipelineSettings {
    /// Reads a settings file; unknown keys and bad values are errors naming the file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the configuration {}", path.display()))?;
        let s: PipelineSettings = toml::from_str(&text)
            .with_context(|| format!("{}: invalid configuration", path.display()))?;
        s.validate()
            .with_context(|| format!("{}: invalid configuration", path.display()))?;
        Ok(s)
    }

    /// The small profile for a 320x240 rig on a microcontroller
    /// (`configs/embedded-320x240.toml`, built in).
    pub fn embedded() -> Self {
        toml::from_str(include_str!("../../configs/embedded-320x240.toml"))
            .expect("configs/embedded-320x240.toml is valid (tested)")
    }

    /// Reads `path` when given, else the defaults.
    pub fn load(path: Option<&Path>) -> Result<Self> {
        path.map_or_else(|| Ok(Self::default()), Self::from_file)
    }

    /// Checks every setting with the limits the firmware applies (one place for
    /// both, [`Configure::validate`]), before anything is sent.
    pub fn validate(&self) -> Result<()> {
        // The rig does not matter for the settings' ranges; the maximal disparity,
        // when not set, follows the image width.
        let rig = Rig::rectified(Interior::pinhole_px(640, 480, 700.0), 0.5);
        self.configure(&rig)
            .validate()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(())
    }

    /// The configuration message for `rig` (datum: the settings' or omega 90 at the
    /// origin; the calibration's precision unstated).
    pub fn configure(&self, rig: &Rig) -> Configure {
        self.configure_for(
            rig,
            &crate::dataset::default_datum(),
            &CalibrationPrecision::UNSTATED,
        )
    }

    /// The datum the traverse starts from: the settings' `[datum]` when given, else the
    /// dataset's. The poses written are relative to it.
    pub fn datum_for(&self, dataset_datum: &Pose) -> Pose {
        self.datum.map_or(*dataset_datum, |d| d.pose())
    }

    /// The configuration message for a dataset's rig, datum and calibration precision
    /// (the settings' `[datum]`, when given, wins over `dataset_datum`).
    pub fn configure_for(
        &self,
        rig: &Rig,
        dataset_datum: &Pose,
        precision: &CalibrationPrecision,
    ) -> Configure {
        let (w, h) = (rig.left.width_px, rig.left.height_px);
        let datum = self.datum_for(dataset_datum);
        Configure {
            version: CONFIG_VERSION,
            traverse: TraverseSettings {
                mode: self.mode.wire(),
                estimate_rig: self.estimate_rig,
                sigma_px: self.sigma_px,
                datum: datum.to_params(),
                check_calibration: self.check_calibration,
                calibration_precision: *precision,
            },
            rig: *rig,
            pipeline: Pipeline {
                max_width: w.min(u16::MAX as u32) as u16,
                max_height: h.min(u16::MAX as u32) as u16,
                pixel_bytes: 1,
                octaves: self.octaves,
                scales_per_octave: self.scales_per_octave,
                keypoints_per_image: self.keypoints_per_image,
                window_len: self.window,
                track_capacity: self.track_capacity,
                contrast_threshold: self.contrast_threshold,
                edge_ratio: self.edge_ratio,
                match_ratio: self.match_ratio,
                max_disparity_px: self
                    .max_disparity_px
                    .unwrap_or(w as f32 * TRAVERSE_DISPARITY_FRACTION),
                fine_octave: self.fine_octave,
                fixed_epochs: Some(self.fixed_epochs),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_embedded_profile_is_the_file() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/embedded-320x240.toml");
        let file = PipelineSettings::from_file(&path).unwrap();
        let built_in = PipelineSettings::embedded();
        built_in.validate().unwrap();
        assert_eq!(format!("{built_in:?}"), format!("{file:?}"));
    }

    #[test]
    fn reads_partial_files_and_names_bad_keys() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("ok.toml");
        std::fs::write(&ok, "keypoints_per_image = 300\nwindow = 4\n").unwrap();
        let s = PipelineSettings::from_file(&ok).unwrap();
        assert_eq!((s.keypoints_per_image, s.window, s.octaves), (300, 4, 4));
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, "keypoints = 300\n").unwrap();
        let err = format!("{:#}", PipelineSettings::from_file(&bad).unwrap_err());
        assert!(
            err.contains("bad.toml") && err.contains("keypoints"),
            "{err}"
        );
        std::fs::write(&bad, "window = 1\n").unwrap();
        let err = format!("{:#}", PipelineSettings::from_file(&bad).unwrap_err());
        assert!(err.contains("window must be at least 2"), "{err}");
        std::fs::write(&bad, "max_disparity_px = 0\n").unwrap();
        let err = format!("{:#}", PipelineSettings::from_file(&bad).unwrap_err());
        assert!(
            err.contains("max_disparity_px must be at least 1 pixel"),
            "{err}"
        );
        std::fs::write(&bad, "mode = \"seed1999\"\n").unwrap();
        let err = format!("{:#}", PipelineSettings::from_file(&bad).unwrap_err());
        assert!(err.contains("seed1999"), "{err}");
    }

    #[test]
    fn mode_rig_sigma_and_datum_reach_the_configure_message() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("seed.toml");
        std::fs::write(
            &f,
            "mode = \"seed2006\"\nestimate_rig = true\nsigma_px = 0.8\nfine_octave = true\n\
             [datum]\nomega_deg = 92.0\nphi_deg = 1.0\nkappa_deg = -2.0\nposition_m = [5.0, 6.0, 1.2]\n",
        )
        .unwrap();
        let s = PipelineSettings::from_file(&f).unwrap();
        let rig = Rig::rectified(
            phototraverse_core::camera::Interior::pinhole_px(320, 240, 300.0),
            0.4,
        );
        let dataset = Pose::from_degrees(90.0, 0.0, 0.0, [1.0, 2.0, 3.0]);
        let c = s.configure_for(&rig, &dataset, &CalibrationPrecision::UNSTATED);
        assert_eq!(c.version, CONFIG_VERSION);
        assert_eq!(c.pipeline.fixed_epochs, Some(TRAVERSE_FIXED_EPOCHS as u16));
        assert_eq!(c.traverse.mode, AdjustMode::Seed2006);
        assert!(c.traverse.estimate_rig);
        assert_eq!(c.traverse.sigma_px, 0.8);
        assert!(c.pipeline.fine_octave);
        let want = Pose::from_degrees(92.0, 1.0, -2.0, [5.0, 6.0, 1.2]).to_params();
        assert_eq!(c.traverse.datum, want);
        // Without [datum] the dataset's datum goes.
        let d = PipelineSettings::default().configure_for(
            &rig,
            &dataset,
            &CalibrationPrecision::UNSTATED,
        );
        assert_eq!(d.traverse.datum, dataset.to_params());
        assert_eq!(d.traverse.mode, AdjustMode::Window);
        assert!(!d.pipeline.fine_octave);
    }
}
