//! The `arlux` command line: parses arguments and calls the library.

#![forbid(unsafe_code)]

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Prints a line to stdout, failing (not panicking) when the reader has
/// gone: `main` turns a broken pipe into a quiet exit.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)?;
    }};
}

mod common;
mod compare;
mod flags;
mod gonio;
mod hdr;
mod ids;
mod info;
mod merge;
mod motion;
mod outputs;
mod progress;
mod radiosity;
mod render;
mod serve;
mod sweep;
mod timing;

use outputs::Output;
use timing::{report_timings, stage};

#[derive(Parser)]
#[command(
    name = "arlux",
    version,
    about = "Per-pixel differential rendering of virtual objects and lights into photographs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Report wall time per stage (load, tracer, estimation, radiosity,
    /// pixel data array, composite, write, ...) and peak memory, on stderr.
    #[arg(long, global = true)]
    timings: bool,
    /// Make the warnings about likely wrong inputs (lights that do not fit
    /// the photo, a clipped photo) errors: nothing is written.
    #[arg(long, global = true)]
    strict: bool,
    /// Progress on stderr: on a terminal only (auto), always (as plain
    /// lines in a pipe or a job's log), or never.
    #[arg(long, global = true, value_enum, default_value_t = progress::ProgressMode::Auto)]
    progress: progress::ProgressMode,
}

#[derive(Subcommand)]
enum Command {
    /// Describe a scene: surfaces, triangles, lights, objects, variants, motions, the photo's range.
    Info(info::Args),
    /// Colour each pixel by the surface it sees, beside the photo with the surfaces' outlines: how to check that the model registers with the photo.
    Ids(ids::Args),
    /// The augmented photo of a variant: virtual objects inserted, lights changed or added, by per-pixel differential rendering (or, with --method texture, shadow-free textures × B/D).
    Render(render::Args),
    /// Render a motion: the first pose in full, then an incremental update per pose, writing DIR/NAME_000.exr, NAME_001.exr, ...
    Motion(motion::Args),
    /// Merge 8-bit exposure brackets into an HDR radiance map (Debevec & Malik): the camera response per channel, then a weighted merge. Radiance is relative (the base exposure time is unknown).
    Hdr(hdr::Args),
    /// Re-render the photo from the model alone (reflectances estimated from the photo × (direct + indirect light)), with a mesh view; reports patches, links, iterations, residual and time per stage.
    Radiosity(radiosity::Args),
    /// Recover the goniometric of the scene's light marked intensity = "reconstruct" from the photo (Grosch §2.3), with the reflectances it needs on the way; writes it as an IES LM-63 file.
    Gonio(gonio::Args),
    /// Error against run time: render a variant (or a motion) over a grid of quality settings, measure each against its reference, and write DIR/sweep.csv and DIR/sweep.png (error against time, Pareto front marked).
    Sweep(sweep::Args),
    /// Assemble a farm's pieces: crops of one frame (render --crop) into the frame's EXR, or a sweep's shard tables (sweep --shard) into the whole sweep's CSV.
    Merge(merge::Args),
    /// A local web page over an editing session: click the photo to stand an object there, drag to slide it, turn, scale, hide it; scale the lights; save the state as a variant; write full EXRs. Each change is an incremental update.
    Serve(serve::Args),
    /// Error of an image against a reference: RMSE and relative RMSE in linear radiance, PSNR of the sRGB-encoded images, and their means.
    Compare(compare::Args),
}

/// On SIGINT, SIGTERM or SIGHUP: removes the run's temporary files and
/// exits with 128 + the signal's number, as a shell reports a killed command.
fn remove_temporaries_on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
        return;
    };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            arlux::util::cleanup::remove_all();
            std::process::exit(128 + signal);
        }
    });
}

fn main() -> ExitCode {
    let start = std::time::Instant::now();
    // A panic the library contains (a third-party parser's bug on a bad
    // file) becomes an error message, not a backtrace.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !arlux::util::guard::is_containing() {
            default_hook(info);
        }
    }));
    remove_temporaries_on_signals();
    let cli = match stage("arguments", Cli::try_parse) {
        Ok(cli) => cli,
        Err(e) => return argument_error(e),
    };
    let timings = cli.timings;
    let json_command = cli.command.json_name();
    common::set_strict(cli.strict);
    progress::set_mode(cli.progress);
    // Every command shows its stages while it runs, on a terminal (motion
    // and sweep count their poses and settings instead).
    let spinner = match &cli.command {
        Command::Render(_) => Some("render"),
        Command::Radiosity(_) => Some("radiosity"),
        Command::Gonio(_) => Some("gonio"),
        Command::Hdr(_) => Some("hdr"),
        Command::Ids(_) => Some("ids"),
        Command::Merge(_) => Some("merge"),
        Command::Compare(_) => Some("compare"),
        Command::Info(_) => Some("info"),
        _ => None,
    }
    .map(progress::spinner);
    let result = run(cli);
    if let Some(s) = spinner {
        s.finish_and_clear();
    }
    if timings {
        report_timings(start.elapsed());
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A closed pipe (`arlux info | head`) is not a failure.
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            if let Some(command) = json_command {
                let _ = common::emit(command, error_json(&e));
            }
            ExitCode::from(2)
        }
    }
}

/// Arguments the parser refused: its message on stderr, status 2, and with
/// `--json` among them the error object `docs/json.md` promises on stdout
/// (help and version are printed as asked, status 0).
fn argument_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
        e.exit();
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--json") {
        let command = args
            .iter()
            .find(|a| !a.starts_with('-'))
            .map_or("arlux", String::as_str);
        let text = e.render().to_string();
        let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
        let message = lines.next().unwrap_or("").trim_start_matches("error: ");
        let _ = common::emit(
            command,
            serde_json::json!({ "error": { "message": message, "causes": lines.collect::<Vec<_>>() } }),
        );
    }
    let _ = e.print();
    ExitCode::from(2)
}

impl Command {
    /// The command's name when it was asked for `--json`.
    fn json_name(&self) -> Option<&'static str> {
        let (name, json) = match self {
            Command::Info(a) => ("info", a.json),
            Command::Ids(a) => ("ids", a.json),
            Command::Render(a) => ("render", a.json),
            Command::Motion(a) => ("motion", a.json),
            Command::Hdr(a) => ("hdr", a.json),
            Command::Radiosity(a) => ("radiosity", a.json),
            Command::Gonio(a) => ("gonio", a.json),
            Command::Sweep(a) => ("sweep", a.json),
            Command::Merge(a) => ("merge", a.json),
            Command::Compare(a) => ("compare", a.json),
            Command::Serve(a) => ("serve", a.json),
        };
        json.then_some(name)
    }
}

/// A failed run as JSON: the message, and where arlux's own error names
/// them, the file and the key or line to edit (`docs/json.md`).
fn error_json(e: &anyhow::Error) -> serde_json::Value {
    let mut error = serde_json::json!({
        "message": e.to_string(),
        "causes": e.chain().skip(1).map(|c| c.to_string()).collect::<Vec<_>>(),
    });
    if let Some(a) = e.chain().find_map(|c| c.downcast_ref::<arlux::Error>()) {
        error["file"] = serde_json::json!(a.file.display().to_string());
        match &a.location {
            arlux::error::Location::Key(k) => error["key"] = serde_json::json!(k),
            arlux::error::Location::Line(l) => error["line"] = serde_json::json!(l),
            arlux::error::Location::File => {}
        }
    }
    serde_json::json!({ "error": error })
}

/// An optional output file.
fn optional<'a>(
    path: &'a Option<std::path::PathBuf>,
    flag: &'static str,
    extensions: &'static [&'static str],
) -> Option<Output<'a>> {
    path.as_deref().map(|p| Output::file(p, flag, extensions))
}

/// The files and folders a command will write.
fn outputs(command: &Command) -> Vec<Output<'_>> {
    const EXR: &[&str] = &["exr"];
    const PNG: &[&str] = &["png"];
    let files = match command {
        Command::Ids(a) => vec![
            Some(Output::file(&a.output, "-o", PNG)),
            optional(&a.exr, "--exr", EXR),
        ],
        Command::Render(a) => vec![
            Some(Output::file(&a.output, "-o", EXR)),
            optional(&a.png, "--png", PNG),
            a.aov.as_deref().map(|p| Output::folder(p, "--aov")),
        ],
        Command::Hdr(a) => vec![
            Some(Output::file(&a.output, "-o", EXR)),
            optional(&a.response, "--response", &["csv"]),
        ],
        Command::Radiosity(a) => vec![
            Some(Output::file(&a.output, "-o", EXR)),
            optional(&a.mesh, "--mesh", PNG),
        ],
        Command::Gonio(a) => vec![
            Some(Output::file(&a.output, "-o", &["ies"])),
            optional(&a.plot, "--plot", PNG),
        ],
        Command::Motion(a) => vec![
            Some(Output::folder(&a.output, "-o")),
            optional(&a.debug_blocks, "--debug-blocks", PNG),
        ],
        Command::Sweep(a) => vec![Some(Output::folder(&a.output, "-o"))],
        Command::Merge(a) => vec![
            Some(Output::file(&a.output, "-o", &["exr", "csv"])),
            optional(&a.plot, "--plot", PNG),
        ],
        Command::Serve(a) => vec![a.out.as_deref().map(|p| Output::folder(p, "--out"))],
        Command::Info(_) | Command::Compare(_) => vec![],
    };
    files.into_iter().flatten().collect()
}

fn run(cli: Cli) -> Result<()> {
    // Refuse outputs that cannot be written, or would overwrite each
    // other, before any work, not after it.
    outputs::check(&outputs(&cli.command))?;
    match &cli.command {
        Command::Info(a) => info::run(a),
        Command::Ids(a) => ids::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Render(a) => render::run(a),
        Command::Hdr(a) => hdr::run(a),
        Command::Motion(a) => motion::run(a),
        Command::Sweep(a) => sweep::run(a),
        Command::Gonio(a) => gonio::run(a),
        Command::Radiosity(a) => radiosity::run(a),
        Command::Merge(a) => merge::run(a),
        Command::Serve(a) => serve::run(a),
    }
}
