//! Progress of long commands (bake, reference, accuracy bench): an indicatif bar when stderr is
//! a terminal, else plain lines on stderr, so that logs, pipes and CI show progress too.
//!
//! A plain line reads `NAME: POS/LEN (P %), T s elapsed, M GiB resident (peak P GiB)` (the
//! memory where the system tells it: Linux); one is printed when the work starts,
//! then whenever [`PLAIN_STEP`] of it (and at least [`PLAIN_MIN_GAP`] of time) or
//! [`PLAIN_INTERVAL`] of time has passed since the last line, and once at the end.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Fraction of the work between two plain progress lines.
pub const PLAIN_STEP: f64 = 0.10;
/// Time between two plain progress lines when the work is slow.
pub const PLAIN_INTERVAL: Duration = Duration::from_secs(5);
/// Shortest time between two plain progress lines (a fast phase prints its first and last).
pub const PLAIN_MIN_GAP: Duration = Duration::from_secs(1);

/// The bar template every subcommand uses: `NAME [====>   ] POS/LEN elapsed eta`.
pub fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template("{msg:24} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
        .expect("valid template")
        .progress_chars("=> ")
}

/// Plain-line state: what was printed last.
struct Plain {
    name: String,
    total: u64,
    pos: u64,
    start: Instant,
    last_time: Instant,
    last_pos: Option<u64>,
    finished: bool,
}

impl Plain {
    /// Prints a line if the work moved by [`PLAIN_STEP`] or [`PLAIN_INTERVAL`] passed (always
    /// when `force`).
    fn maybe_print(&mut self, force: bool) {
        let now = Instant::now();
        let step = (self.total as f64 * PLAIN_STEP).ceil().max(1.0) as u64;
        let due = match self.last_pos {
            None => true,
            Some(last) => {
                let since = now - self.last_time;
                (self.pos >= last + step && since >= PLAIN_MIN_GAP)
                    || (self.pos > last && since >= PLAIN_INTERVAL)
            }
        };
        if force || due {
            let pct = 100.0 * self.pos as f64 / self.total.max(1) as f64;
            use ortm::io::limits::{gib, resident_memory};
            let memory = match resident_memory() {
                Some((now, peak)) => {
                    format!(", {:.2} GiB resident (peak {:.2} GiB)", gib(now), gib(peak))
                }
                None => String::new(),
            };
            eprintln!(
                "{}: {}/{} ({pct:.0} %), {:.1} s elapsed{memory}",
                self.name,
                self.pos,
                self.total,
                (now - self.start).as_secs_f64()
            );
            self.last_time = now;
            self.last_pos = Some(self.pos);
        }
    }
}

/// One phase's progress: a bar on a terminal, plain lines otherwise (see the module docs).
pub struct Progress {
    bar: ProgressBar,
    plain: Option<Mutex<Plain>>,
}

impl Progress {
    /// Progress of `total` steps named `name`; the bar (terminal) or the first line (else)
    /// shows at once.
    pub fn new(total: u64, name: impl Into<String>) -> Self {
        let name = name.into();
        if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(total)
                .with_style(bar_style())
                .with_message(name);
            return Self { bar, plain: None };
        }
        let now = Instant::now();
        let mut plain = Plain {
            name,
            total,
            pos: 0,
            start: now,
            last_time: now,
            last_pos: None,
            finished: false,
        };
        plain.maybe_print(false);
        Self {
            bar: ProgressBar::hidden(),
            plain: Some(Mutex::new(plain)),
        }
    }

    /// No progress shown (before the first phase starts).
    pub fn hidden() -> Self {
        Self {
            bar: ProgressBar::hidden(),
            plain: None,
        }
    }

    /// Moves the progress forward by `n` steps.
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
        if let Some(p) = &self.plain {
            let mut p = p.lock().expect("progress lock");
            p.pos = p.pos.saturating_add(n).min(p.total);
            p.maybe_print(false);
        }
    }

    /// Sets the progress to `pos` steps done.
    pub fn set_position(&self, pos: u64) {
        self.bar.set_position(pos);
        if let Some(p) = &self.plain {
            let mut p = p.lock().expect("progress lock");
            p.pos = pos.min(p.total);
            p.maybe_print(false);
        }
    }

    /// Prints a message line above the bar (or plainly on stderr).
    pub fn println(&self, m: impl AsRef<str>) {
        if self.bar.is_hidden() {
            eprintln!("{}", m.as_ref());
        } else {
            self.bar.println(m);
        }
    }

    /// Ends the phase: the bar stays drawn; in plain mode the last line is printed (once).
    pub fn finish(&self) {
        self.bar.finish();
        self.plain_final();
    }

    /// Ends the phase and removes the bar; in plain mode the last line is printed (once).
    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
        self.plain_final();
    }

    fn plain_final(&self) {
        if let Some(p) = &self.plain {
            let mut p = p.lock().expect("progress lock");
            if !p.finished {
                p.finished = true;
                if p.last_pos != Some(p.pos) {
                    p.maybe_print(true);
                }
            }
        }
    }
}
