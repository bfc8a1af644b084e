//! `arlux merge`: Assemble a farm's pieces into the whole: crops of one frame (`render --crop`) into the frame's EXR, or a sweep's shard tables (`sweep --shard`) into the whole sweep's CSV.

use std::path::PathBuf;

use anyhow::{Result, bail};

use arlux::image_io;
use arlux::sweep::{SweepTable, merge_tables, plot};

use crate::common::{Report, print_report};
use crate::timing::*;

/// Arguments of `arlux merge`.
#[derive(clap::Args)]
pub struct Args {
    /// The pieces: EXR crops of one frame, or CSV tables of one sweep's shards.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// The whole: an EXR (from crops) or a CSV (from shard tables).
    #[arg(short, long)]
    pub output: PathBuf,
    /// With CSV tables: also the plot of error against time, Pareto front marked.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

fn extension(p: &std::path::Path) -> String {
    p.extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default()
}

pub fn run(args: &Args) -> Result<()> {
    crate::outputs::refuse_inputs(&args.inputs)?;
    let kind = extension(&args.output);
    if let Some(p) = args.inputs.iter().find(|p| extension(p) != kind) {
        bail!(arlux::Error::file(
            p,
            format!("cannot merge into a .{kind}: every input must be a .{kind} too")
        ));
    }
    if kind == "exr" {
        if args.plot.is_some() {
            bail!("--plot draws a sweep: it goes with CSV tables, not EXR crops");
        }
        let merged = stage("merge", || {
            image_io::merge_tiles(&args.inputs, &args.output)
        })?;
        let report = MergeReport::Frame {
            output: args.output.display().to_string(),
            pieces: merged.tiles,
            width: merged.width,
            height: merged.height,
            channels: merged.channels,
        };
        return print_report(&report, args.json);
    }
    let tables = stage("read", || -> Result<Vec<(PathBuf, SweepTable)>> {
        args.inputs
            .iter()
            .map(|p| {
                let text = std::fs::read_to_string(p).map_err(|e| arlux::Error::io(p, &e))?;
                Ok((p.clone(), SweepTable::from_csv(&text, p)?))
            })
            .collect()
    })?;
    let table = stage("merge", || merge_tables(&tables))?;
    stage("write", || -> Result<()> {
        image_io::write_atomic(&args.output, table.to_csv().as_bytes())?;
        if let Some(png) = &args.plot {
            let title = format!(
                "{}: error against time ({} settings)",
                table.reference,
                table.rows.len()
            );
            plot(&table.rows, &title, png)?;
        }
        Ok(())
    })?;
    let report = MergeReport::Sweep {
        output: args.output.display().to_string(),
        pieces: tables.len(),
        settings: table.rows.len(),
        pareto: table.rows.iter().filter(|r| r.pareto).count(),
    };
    print_report(&report, args.json)
}

/// `arlux merge`'s report: a frame from crops, or a sweep from shard tables.
#[derive(serde::Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
enum MergeReport {
    Frame {
        output: String,
        pieces: usize,
        width: u32,
        height: u32,
        channels: usize,
    },
    Sweep {
        output: String,
        pieces: usize,
        settings: usize,
        /// Rows on the Pareto front.
        pareto: usize,
    },
}

impl Report for MergeReport {
    const COMMAND: &'static str = "merge";

    fn text(&self) -> Vec<String> {
        vec![match self {
            MergeReport::Frame {
                output,
                pieces,
                width,
                height,
                channels,
            } => format!(
                "merged {pieces} crops into {output} ({width}×{height}, {channels} channels)"
            ),
            MergeReport::Sweep {
                output,
                pieces,
                settings,
                pareto,
            } => format!(
                "merged {pieces} shard tables into {output} ({settings} settings, {pareto} on the Pareto front)"
            ),
        }]
    }
}
