//! The command line's observer: a spinner on a terminal only (docs/reference/case.md: quiet when not one),
//! through indicatif, and the counting allocator's heap figures for report.json.

use facesim::meter::HeapProbe;
use facesim::observe::Observer;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::Duration;

pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A spinner on stderr when it is a terminal; silent otherwise.
    pub fn auto() -> Self {
        if std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar.enable_steady_tick(Duration::from_millis(120));
            Progress { bar: Some(bar) }
        } else {
            Progress { bar: None }
        }
    }
}

impl Observer for Progress {
    fn started(&self, what: &str) {
        if let Some(b) = &self.bar {
            b.set_message(what.to_string());
        }
    }

    fn done(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }

    fn heap(&self) -> Option<&dyn HeapProbe> {
        facesim::meter::counted_heap()
    }

    fn warn(&self, msg: &str) {
        eprintln!("warning: {msg}");
    }
}
