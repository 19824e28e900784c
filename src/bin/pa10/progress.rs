//! Progress on the terminal for work that takes more than a moment (`pa10 plan`, `pa10
//! calibrate`, `pa10 accuracy`, `pa10
//! discover`, `pa10 identify`, `pa10 collect run`): a spinner with the elapsed time and the
//! phase, or a bar with a count, on standard error and only when it is a terminal and the
//! command's output is not `--json` (piped, under `--json` and in tests nothing is drawn, so the
//! output stays what it was).

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Standard error, or nowhere when `quiet` (`--json`).
fn target(quiet: bool) -> ProgressDrawTarget {
    if quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    }
}

/// A spinner saying `msg`, ticking by itself until it is finished; drawn nowhere when `quiet`.
pub fn spinner(msg: &str, quiet: bool) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(None, target(quiet));
    pb.set_style(
        ProgressStyle::with_template("{spinner} {elapsed:>3} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

/// A bar over `len` steps saying `msg`; drawn nowhere when `quiet`.
pub fn bar(len: u64, msg: &str, quiet: bool) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(len), target(quiet));
    pb.set_style(
        ProgressStyle::with_template("{elapsed:>3} [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb.set_message(msg.to_string());
    pb
}
