//! Progress bars on stderr; indicatif hides them when stderr is not a terminal.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar for long work with a message, a count and an estimate of the time left.
pub fn bar() -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg:24} [{bar:40}] {human_pos}/{human_len} ({eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar
}

/// `bar` as the scene library's progress reporter (the library draws nothing itself).
pub fn for_scene(bar: &ProgressBar) -> scene::Progress {
    scene::Progress::to(Bar(bar.clone()))
}

struct Bar(ProgressBar);

impl scene::ProgressSink for Bar {
    fn set_length(&self, length: u64) {
        self.0.set_length(length);
    }
    fn set_position(&self, position: u64) {
        self.0.set_position(position);
    }
    fn inc(&self, delta: u64) {
        self.0.inc(delta);
    }
    fn set_message(&self, message: &str) {
        self.0.set_message(message.to_string());
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}
