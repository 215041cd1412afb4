//! Ctrl-C (SIGINT) and SIGTERM during a run: the run stops between epochs and writes
//! every output for the epochs done, marked as interrupted. A second signal ends the
//! process at once (status 130), for a run stuck waiting on its link.
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// The exit status of a process ended by SIGINT, by the shell's convention (128 + 2).
pub const EXIT_STATUS: i32 = 130;

/// Installs the handler (once per process; later calls do nothing).
pub fn install() {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let installed = ctrlc::set_handler(|| {
            if REQUESTED.swap(true, Ordering::SeqCst) {
                std::process::exit(EXIT_STATUS);
            }
            eprintln!(
                "\nphototraverse: interrupted: stopping after this epoch and writing the \
                 outputs (again to quit at once)"
            );
        });
        if let Err(e) = installed {
            eprintln!("phototraverse: warning: Ctrl-C will not save the outputs: {e}");
        }
    });
}

/// Whether a signal asked the run to stop.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// After the outputs of an interrupted run are written: says so and ends the process
/// with [`EXIT_STATUS`], so that a script sees the run did not complete.
pub fn exit_if_interrupted(outcome: &crate::runner::RunOutcome, epochs: usize) {
    if outcome.report.interrupted {
        use std::io::Write;
        let _ = std::io::stdout().flush();
        eprintln!(
            "phototraverse: interrupted after {} of {epochs} epochs; the outputs hold those",
            outcome.report.epochs.len()
        );
        std::process::exit(EXIT_STATUS);
    }
}
