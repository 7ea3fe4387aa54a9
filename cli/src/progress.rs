//! Progress bars, one per running job: frames done against frames expected,
//! with frames per second and time left. indicatif draws them only on a
//! terminal, and `--quiet` hides them; messages go around them.

use std::fmt::Write;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

/// The bars of one run of the tool.
pub struct Bars {
    multi: MultiProgress,
    quiet: bool,
}

impl Bars {
    pub fn new(quiet: bool) -> Bars {
        let target = if quiet {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        };
        Bars {
            multi: MultiProgress::with_draw_target(target),
            quiet,
        }
    }

    /// A bar for one job, labelled with its name, counting until its length is known.
    pub fn add(&self, name: &str) -> Bar {
        let bar = self.multi.add(ProgressBar::no_length());
        bar.set_style(style("{prefix} {spinner} {pos} frames, {fps} fps"));
        bar.set_prefix(name.to_string());
        Bar(bar)
    }

    /// A line of live status below the notes, redrawn in place.
    pub fn status_line(&self) -> StatusLine {
        let bar = self.multi.add(ProgressBar::no_length());
        bar.set_style(style("{spinner} {msg}"));
        StatusLine(bar)
    }

    /// A warning or note on standard error, above the bars.
    pub fn note(&self, line: &str) {
        if !self.quiet {
            self.multi.suspend(|| eprintln!("{line}"));
        }
    }

    /// A result on standard output, above the bars.
    pub fn result(&self, line: &str) {
        if !self.quiet {
            self.multi.suspend(|| println!("{line}"));
        }
    }
}

pub struct Bar(ProgressBar);

impl Bar {
    /// `done` frames so far, of `expected()` frames: asked until the input's length is known.
    pub fn update(&self, done: u64, expected: impl FnOnce() -> Option<u64>) {
        if self.0.length().is_none()
            && let Some(n) = expected()
        {
            self.0.set_length(n);
            self.0.set_style(style(
                "{prefix} [{bar:30}] {pos}/{len} frames, {fps} fps, {eta} left",
            ));
        }
        self.0.set_position(done);
    }

    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template)
        // The templates are constants of this file; a typo in one shows the default style.
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
        .with_key("fps", |s: &ProgressState, w: &mut dyn Write| {
            let _ = write!(w, "{:.1}", s.per_sec());
        })
}

/// A line of text that says how a live job is doing, redrawn in place.
pub struct StatusLine(ProgressBar);

impl StatusLine {
    pub fn say(&self, text: &str) {
        self.0.set_message(text.to_string());
        self.0.tick();
    }

    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}
