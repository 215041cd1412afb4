//! The embedded profile (configs/embedded-320x240.toml) at 320x240: the firmware's
//! predicted and measured memory, frame buffers excluded, within 512 KiB, and the
//! traverse still orients the epochs of a synthetic sequence.
use phototraverse_host::dataset::Dataset;
use phototraverse_host::link::LinkOptions;
use phototraverse_host::pipeline::PipelineSettings;
use phototraverse_host::report::EpochStatus;
use phototraverse_host::runner::{run_dataset, RunOptions};
use phototraverse_host::synth::{generate, SynthOptions};
use std::path::Path;

const LIMIT: usize = 512 * 1024;

fn profile() -> PipelineSettings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/embedded-320x240.toml");
    PipelineSettings::load(Some(&path)).expect("the profile parses")
}

#[test]
fn embedded_profile_fits_512k_predicted_and_measured_at_320x240() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("s320");
    let mut opts = SynthOptions::new("straight", data.clone());
    opts.frames = Some(5);
    opts.size = Some((320, 240));
    let s = generate(&opts).unwrap();
    assert_eq!((s.width, s.height), (320, 240));

    let ds = Dataset::open(&data).unwrap();
    let run = RunOptions {
        link: LinkOptions::default(),
        settings: profile(),
        max_epochs: None,
        progress: false,
    };
    let outcome = run_dataset(&ds, &tmp.path().join("out"), &run).unwrap();
    let mem = &outcome.report.memory;
    let frames: usize = mem
        .iter()
        .filter(|m| m.kind == "frame")
        .map(|m| m.predicted_bytes)
        .sum();
    assert_eq!(frames, 2 * (320 * 240), "two 8-bit frames");
    let total = mem
        .iter()
        .find(|m| m.name.starts_with("total"))
        .expect("a total line");
    let predicted = total.predicted_bytes - frames;
    let measured = total
        .measured_bytes
        .expect("the firmware reports its high water")
        - frames;
    assert!(
        measured <= predicted && predicted <= LIMIT,
        "measured {measured} <= predicted {predicted} <= {LIMIT}"
    );
    // The prediction is the arena's carving, padding aside: no more than a few bytes
    // per buffer apart.
    assert!(predicted - measured < 256, "{predicted} vs {measured}");

    // Small, but still a traverse: every epoch adjusted from its images (none left at
    // the motion prediction), each on some tie points. (Few at this size: epochs with
    // fewer than the traverse's 12 are flagged, not lost.)
    assert_eq!(outcome.report.epochs.len(), 5);
    for e in &outcome.report.epochs[1..] {
        assert!(
            matches!(e.status, EpochStatus::Ok | EpochStatus::Flagged),
            "epoch {}: {:?} ({:?})",
            e.epoch,
            e.status,
            e.note
        );
        assert!(
            e.tie_points >= 6,
            "epoch {}: {} tie points",
            e.epoch,
            e.tie_points
        );
    }
}
