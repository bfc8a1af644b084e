//! Progress on stderr: drawn on a terminal and silent in a pipe, or forced
//! either way with `--progress always|never` (a job's log, a test).

use std::io::Write as _;
use std::sync::OnceLock;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle, TermLike};

/// When progress is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum ProgressMode {
    /// On a terminal only.
    #[default]
    Auto,
    /// Always, as plain lines where stderr is not a terminal.
    Always,
    Never,
}

static MODE: OnceLock<ProgressMode> = OnceLock::new();

pub(crate) fn set_mode(mode: ProgressMode) {
    let _ = MODE.set(mode);
}

/// Stderr as indicatif's terminal whatever it is: each new state of the
/// line printed once, as a line of its own (no cursor movement in a log).
#[derive(Debug, Default)]
struct PlainStderr {
    last: std::sync::Mutex<String>,
}

impl PlainStderr {
    fn line(&self, s: &str) -> std::io::Result<()> {
        let s = s.trim_end();
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if s.is_empty() || *last == s {
            return Ok(());
        }
        *last = s.to_string();
        writeln!(std::io::stderr(), "{s}")
    }
}

impl TermLike for PlainStderr {
    fn width(&self) -> u16 {
        100
    }
    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn write_line(&self, s: &str) -> std::io::Result<()> {
        self.line(s)
    }
    fn write_str(&self, s: &str) -> std::io::Result<()> {
        self.line(s)
    }
    fn clear_line(&self) -> std::io::Result<()> {
        Ok(())
    }
    fn flush(&self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

fn target() -> ProgressDrawTarget {
    match MODE.get().copied().unwrap_or_default() {
        ProgressMode::Auto => ProgressDrawTarget::stderr(),
        // Twice a second: a log gets a line per half second, not per tick.
        ProgressMode::Always => {
            ProgressDrawTarget::term_like_with_hz(Box::<PlainStderr>::default(), 2)
        }
        ProgressMode::Never => ProgressDrawTarget::hidden(),
    }
}

/// A bar over `len` items named `unit` (`poses`, `settings`).
pub(crate) fn progress_bar(len: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(Some(len), target());
    let template = format!("{{bar:30}} {{pos}}/{{len}} {unit}, {{elapsed}} {{msg}}");
    bar.set_style(
        ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// A spinner for a command of unknown length, saying which stage runs
/// (the library's stages as they start) and for how long.
pub(crate) fn spinner(command: &str) -> ProgressBar {
    let bar = stage_spinner(command);
    let shown = bar.clone();
    arlux::util::stages::observe(move |stage| shown.set_message(stage.to_string()));
    bar
}

/// A spinner for `command` whose stages the caller sets (`arlux serve`,
/// whose stage observer also tells the page).
pub(crate) fn stage_spinner(command: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(None, target());
    // In a log (plain lines) a line per stage: no spinner or clock, whose
    // every tick would be a line of its own.
    let plain = MODE.get() == Some(&ProgressMode::Always);
    let template = match plain {
        true => "{prefix}: {msg}",
        false => "{spinner} {prefix}: {msg} ({elapsed})",
    };
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_prefix(command.to_string());
    if !plain {
        bar.enable_steady_tick(Duration::from_millis(250));
    }
    bar
}
