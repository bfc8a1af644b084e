//! The `arlux` command line: parses arguments and calls the library.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Result, bail};
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
mod gonio;
mod hdr;
mod ids;
mod info;
mod motion;
mod radiosity;
mod render;
mod sweep;
mod timing;

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
    /// Error of an image against a reference: RMSE and relative RMSE in linear radiance, PSNR of the sRGB-encoded images, and their means.
    Compare(compare::Args),
}

fn main() -> ExitCode {
    let start = std::time::Instant::now();
    let cli = stage("arguments", Cli::parse);
    let timings = cli.timings;
    let result = run(cli);
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
            ExitCode::from(2)
        }
    }
}

/// The files a command will write (folders it creates itself are not here).
fn output_files(command: &Command) -> Vec<&Path> {
    let files = match command {
        Command::Ids(a) => vec![Some(&a.output), a.exr.as_ref()],
        Command::Render(a) => vec![Some(&a.output), a.png.as_ref()],
        Command::Hdr(a) => vec![Some(&a.output), a.response.as_ref()],
        Command::Radiosity(a) => vec![Some(&a.output), a.mesh.as_ref()],
        Command::Gonio(a) => vec![Some(&a.output), a.plot.as_ref()],
        Command::Motion(a) => vec![a.debug_blocks.as_ref()],
        Command::Info(_) | Command::Compare(_) | Command::Sweep(_) => vec![],
    };
    files.into_iter().flatten().map(|p| p.as_path()).collect()
}

fn run(cli: Cli) -> Result<()> {
    // Refuse an output whose folder is missing before any work, not after it.
    for file in output_files(&cli.command) {
        let dir = file
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if !dir.is_dir() {
            bail!(arlux::Error::file(
                file,
                format!("cannot write: the folder {} does not exist", dir.display())
            ));
        }
    }
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
    }
}
