//! Pipeline settings a user gives in a TOML file (`--config FILE`) and the
//! `Configure` message they become.
use anyhow::{Context, Result};
use phototraverse_core::camera::Rig;
use phototraverse_core::protocol::messages::{Configure, Pipeline, CONFIG_VERSION};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Pipeline settings; every key is optional (defaults in brackets).
///
/// ```toml
/// keypoints_per_image = 1000   # features kept per image
/// octaves = 4                  # scale-space octaves
/// scales_per_octave = 3
/// contrast_threshold = 0.04    # DoG contrast, grey levels / 255
/// edge_ratio = 10.0            # principal curvature ratio
/// match_ratio = 0.8            # Lowe's ratio
/// max_disparity_px = 320.0     # rectified rigs: disparity search range
/// window = 8                   # epochs in the adjustment window
/// track_capacity = 600         # tracks kept at once
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineSettings {
    pub keypoints_per_image: u32,
    pub octaves: u8,
    pub scales_per_octave: u8,
    pub contrast_threshold: f32,
    pub edge_ratio: f32,
    pub match_ratio: f32,
    /// `None`: half the image width.
    pub max_disparity_px: Option<f32>,
    pub window: u16,
    pub track_capacity: u32,
}

impl Default for PipelineSettings {
    fn default() -> Self {
        PipelineSettings {
            keypoints_per_image: 1000,
            octaves: 4,
            scales_per_octave: 3,
            contrast_threshold: 0.04,
            edge_ratio: 10.0,
            match_ratio: 0.8,
            max_disparity_px: None,
            window: 8,
            track_capacity: 600,
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

    /// Reads `path` when given, else the defaults.
    pub fn load(path: Option<&Path>) -> Result<Self> {
        path.map_or_else(|| Ok(Self::default()), Self::from_file)
    }

    pub fn validate(&self) -> Result<()> {
        anyhow::ensure!(
            self.keypoints_per_image >= 8,
            "keypoints_per_image must be at least 8"
        );
        anyhow::ensure!((1..=8).contains(&self.octaves), "octaves must be 1..=8");
        anyhow::ensure!(
            (1..=6).contains(&self.scales_per_octave),
            "scales_per_octave must be 1..=6"
        );
        anyhow::ensure!(
            self.match_ratio > 0.0 && self.match_ratio <= 1.0,
            "match_ratio must be in (0, 1]"
        );
        anyhow::ensure!(self.window >= 2, "window must be at least 2 epochs");
        anyhow::ensure!(
            self.track_capacity >= 8,
            "track_capacity must be at least 8"
        );
        Ok(())
    }

    /// The configuration message for `rig`.
    pub fn configure(&self, rig: &Rig) -> Configure {
        let (w, h) = (rig.left.width_px, rig.left.height_px);
        Configure {
            version: CONFIG_VERSION,
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
                max_disparity_px: self.max_disparity_px.unwrap_or(w as f32 * 0.5),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
