//! Text exports other tools read: `eop.csv`, `points.ply` and E-Foto's two-file import.
use super::fixed::Fixed;
use super::records::{CameraEop, RunReport, TiePoint};
use anyhow::{Context, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

fn create(path: &Path) -> Result<BufWriter<File>> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    Ok(BufWriter::new(file))
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(String::new, |x| format!("{x:.6}"))
}

/// `eop.csv`: one row per image (epoch, camera), angles in degrees, positions in metres,
/// standard deviations, sigma0, observation and tie-point counts, status, and on the
/// left camera's rows the epoch time and the velocity with the speed's standard deviation.
pub fn write_eop_csv(path: &Path, report: &RunReport) -> Result<()> {
    let mut w = create(path)?;
    writeln!(
        w,
        "epoch,camera,omega_deg,phi_deg,kappa_deg,X_m,Y_m,Z_m,\
         sd_omega_deg,sd_phi_deg,sd_kappa_deg,sd_X_m,sd_Y_m,sd_Z_m,\
         sigma0,observations,tie_points,status,\
         time_s,vX_m_s,vY_m_s,vZ_m_s,speed_m_s,sd_speed_m_s"
    )?;
    for e in &report.epochs {
        for (camera, eop) in [("left", &e.left), ("right", &e.right)] {
            let motion = match (camera, &e.velocity) {
                ("left", Some(v)) => format!(
                    "{},{:.5},{:.5},{:.5},{:.5},{}",
                    fmt_opt(e.time),
                    v.v_m_s[0],
                    v.v_m_s[1],
                    v.v_m_s[2],
                    v.speed_m_s,
                    fmt_opt(v.sd_speed_m_s)
                ),
                ("left", None) => format!("{},,,,,", fmt_opt(e.time)),
                _ => ",,,,,".to_string(),
            };
            writeln!(
                w,
                "{},{},{},{},{},{},{},{motion}",
                e.epoch,
                camera,
                eop_fields(eop),
                sigma_fields(eop),
                fmt_opt(e.sigma0),
                format_args!("{},{}", e.observations, e.tie_points),
                serde_json::to_value(e.status)?
                    .as_str()
                    .unwrap_or("unknown"),
            )?;
        }
    }
    w.flush()?;
    Ok(())
}

fn eop_fields(e: &CameraEop) -> String {
    format!(
        "{:.8},{:.8},{:.8},{:.6},{:.6},{:.6}",
        e.omega_deg, e.phi_deg, e.kappa_deg, e.x, e.y, e.z
    )
}

fn sigma_fields(e: &CameraEop) -> String {
    match e.sigma {
        Some(s) => format!(
            "{:.8},{:.8},{:.8},{:.6},{:.6},{:.6}",
            s[0], s[1], s[2], s[3], s[4], s[5]
        ),
        None => ",,,,,".to_string(),
    }
}

/// `points.ply`: ASCII PLY of the tie points (object frame, metres): x y z,
/// their standard deviations (`nan` when the adjustment gave none), the track
/// id and the number of image observations. CloudCompare, MeshLab and Python
/// `plyfile` read it; the extra properties become scalar fields.
pub fn write_ply(path: &Path, points: &[TiePoint]) -> Result<()> {
    let mut w = create(path)?;
    writeln!(
        w,
        "ply\nformat ascii 1.0\ncomment phototraverse tie points, object frame (m)"
    )?;
    writeln!(w, "element vertex {}", points.len())?;
    writeln!(w, "property double x\nproperty double y\nproperty double z")?;
    writeln!(
        w,
        "property float sigma_x\nproperty float sigma_y\nproperty float sigma_z"
    )?;
    writeln!(
        w,
        "property uint id\nproperty uchar observations\nend_header"
    )?;
    for p in points {
        let n = p.measurements.len().min(255);
        let s = p.sigma.unwrap_or([f64::NAN; 3]);
        writeln!(
            w,
            "{:.6} {:.6} {:.6} {} {} {} {} {}",
            p.xyz[0],
            p.xyz[1],
            p.xyz[2],
            fmt_sigma(s[0]),
            fmt_sigma(s[1]),
            fmt_sigma(s[2]),
            p.id,
            n
        )?;
    }
    w.flush()?;
    Ok(())
}

fn fmt_sigma(s: f64) -> String {
    if s.is_finite() {
        format!("{s:.6}")
    } else {
        "nan".into()
    }
}

/// E-Foto's image index of a camera at an epoch, numbered as seed 000 numbers its
/// photographs: odd for the left camera, even for the right (1, 2 at epoch 0).
pub fn efoto_image_index(epoch: usize, camera: u8) -> usize {
    2 * epoch + 1 + camera as usize
}

/// E-Foto's two-file point import (seed 004): `points.txt` (`id  Photogrammetric  E  N  H
/// sE  sN  sH`, tab-separated, local object frame in metres) and `measurements.txt`
/// (`image  point  col  row`, pixels, (0, 0) the centre of the top-left pixel), plus
/// `images.txt` naming the image file of each index.
pub fn write_efoto(dir: &Path, points: &[TiePoint], image_names: &[(usize, String)]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut enh = create(&dir.join("points.txt"))?;
    let mut meas = create(&dir.join("measurements.txt"))?;
    for p in points {
        let s = p.sigma.unwrap_or([0.0; 3]);
        writeln!(
            enh,
            "{}\tPhotogrammetric\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{:.4}",
            p.id, p.xyz[0], p.xyz[1], p.xyz[2], s[0], s[1], s[2]
        )?;
        for m in &p.measurements {
            let image = efoto_image_index(m.epoch, m.camera);
            writeln!(
                meas,
                "{image}\t{}\t{}\t{}",
                p.id,
                Fixed::<3>(m.col),
                Fixed::<3>(m.row)
            )?;
        }
    }
    let mut images = create(&dir.join("images.txt"))?;
    for (index, name) in image_names {
        writeln!(images, "{index}\t{name}")?;
    }
    enh.flush()?;
    meas.flush()?;
    images.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::records::*;
    use super::*;
    use phototraverse_core::camera::Pose;

    fn sample() -> (RunReport, Vec<TiePoint>) {
        let pose = Pose::from_degrees(90.0, 0.5, -1.0, [0.1, 2.0, 1.5]);
        let eop = CameraEop::from_pose(&pose, Some([1e-4, 2e-4, 3e-4, 0.01, 0.02, 0.03]));
        let rec = EpochRecord {
            note: Some("chi-square".into()),
            sigma0: Some(1.05),
            chi2_passed: Some(false),
            observations: 400,
            tie_points: 100,
            keypoints: [1000, 990],
            stereo_matches: 500,
            ..EpochRecord::posed(
                3,
                None,
                EpochStatus::Flagged,
                (eop, CameraEop { sigma: None, ..eop }),
            )
        };
        let report = RunReport {
            epochs: vec![rec],
            ..Default::default()
        };
        let point = TiePoint {
            id: 7,
            xyz: [1.0, 20.0, -1.5],
            sigma: Some([0.01, 0.1, 0.01]),
            measurements: vec![
                ImageMeasurement {
                    epoch: 3,
                    camera: 0,
                    col: 10.25,
                    row: 20.5,
                },
                ImageMeasurement {
                    epoch: 3,
                    camera: 1,
                    col: 5.0,
                    row: 20.5,
                },
            ],
        };
        (report, vec![point])
    }

    #[test]
    fn eop_csv_has_a_row_per_image_with_degrees_and_sigmas() {
        let dir = tempfile::tempdir().unwrap();
        let (report, _) = sample();
        let path = dir.path().join("eop.csv");
        write_eop_csv(&path, &report).unwrap();
        let text = std::fs::read_to_string(path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        let header: Vec<&str> = lines[0].split(',').collect();
        let left: Vec<&str> = lines[1].split(',').collect();
        let right: Vec<&str> = lines[2].split(',').collect();
        assert_eq!(header.len(), left.len());
        assert_eq!(header.len(), right.len());
        assert_eq!(left[..2], ["3", "left"]);
        assert!((left[2].parse::<f64>().unwrap() - 90.0).abs() < 1e-9);
        assert!((left[8].parse::<f64>().unwrap() - 1e-4f64.to_degrees()).abs() < 1e-8);
        assert_eq!(right[8], "");
        assert_eq!(left[17], "flagged");
    }

    #[test]
    fn ply_and_efoto_list_every_point_and_measurement() {
        let dir = tempfile::tempdir().unwrap();
        let (_, points) = sample();
        write_ply(&dir.path().join("p.ply"), &points).unwrap();
        let ply = std::fs::read_to_string(dir.path().join("p.ply")).unwrap();
        assert!(ply.contains("element vertex 1\n"));
        assert!(ply.contains("property float sigma_z\n"));
        assert!(ply
            .trim_end()
            .ends_with("1.000000 20.000000 -1.500000 0.010000 0.100000 0.010000 7 2"));

        let names = vec![(7, "E004.png".to_string()), (8, "D004.png".to_string())];
        write_efoto(&dir.path().join("efoto"), &points, &names).unwrap();
        let meas = std::fs::read_to_string(dir.path().join("efoto/measurements.txt")).unwrap();
        assert_eq!(meas, "7\t7\t10.250\t20.500\n8\t7\t5.000\t20.500\n");
        let enh = std::fs::read_to_string(dir.path().join("efoto/points.txt")).unwrap();
        assert!(enh.starts_with("7\tPhotogrammetric\t1.0000\t20.0000\t-1.5000\t"));
    }
}
