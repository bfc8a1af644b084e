//! `arlux sweep`: Error against run time: render a variant (or a motion) over a grid of quality settings, measure each against its reference, and write DIR/sweep.csv and DIR/sweep.png (error against time, Pareto front marked).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use serde_json::json;

use arlux::image_io::{self};

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux sweep`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    #[arg(long, conflicts_with = "motion", required_unless_present = "motion")]
    pub variant: Option<String>,
    /// Sweep a motion instead: full first pose, updates after; time and mean error over the poses.
    #[arg(long)]
    pub motion: Option<String>,
    #[arg(short, long)]
    pub output: PathBuf,
    /// Six settings from cheapest to dearest, for a smoke check.
    #[arg(long)]
    pub quick: bool,
    /// Runs per setting; the fastest counts (default 3, 1 with --quick).
    #[arg(long)]
    pub repeats: Option<usize>,
    /// Run shard i of n (0-based; `auto/n` reads SLURM_ARRAY_TASK_ID or
    /// JOB_COMPLETION_INDEX): a contiguous share of the grid, written to
    /// DIR/sweep.shard-I-of-N.csv; `arlux merge` joins the shards.
    #[arg(long)]
    pub shard: Option<String>,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let path = args.scene.as_path();
    let variant = args.variant.as_deref();
    let motion = args.motion.as_deref();
    let dir = args.output.as_path();
    let quick = args.quick;
    let repeats = args.repeats.unwrap_or(if quick { 1 } else { 3 });
    let as_json = args.json;
    if repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    use arlux::sweep::{SweepTable, Target, grid, plot, run};
    let scene = stage("load", || load(path, None))?;
    let (target, label) = match (variant, motion) {
        (_, Some(m)) => (Target::Motion { name: m }, format!("motion {m}")),
        (Some(v), None) => (Target::Variant { name: v }, format!("variant {v}")),
        (None, None) => bail!("give --variant or --motion"),
    };
    // Known good before the folder is made: a failed run leaves nothing behind.
    arlux::sweep::reference_files(&scene, &target)?;
    let settings = grid(quick, matches!(target, Target::Variant { .. }));
    let (share, csv_name) = match &args.shard {
        None => (0..settings.len(), "sweep.csv".to_string()),
        Some(text) => {
            let (share, i, n) = shard_range(text, settings.len(), "setting")?;
            (share, format!("sweep.shard-{i}-of-{n}.csv"))
        }
    };
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: could not create the folder", dir.display()))?;
    let bar = crate::progress::progress_bar(share.len() as u64, "settings");
    let rows = stage("renders", || {
        run(
            &scene,
            &target,
            &settings,
            share.clone(),
            repeats,
            |_, row| {
                bar.set_message(format!("last: {:.2} s, RMSE {:.5}", row.seconds, row.rmse));
                bar.inc(1);
            },
        )
    })?;
    bar.finish_and_clear();
    let reference = match &target {
        Target::Variant { name } => scene
            .variant(name)?
            .reference
            .as_ref()
            .map_or(String::new(), |r| rel(&scene, r)),
        Target::Motion { name } => format!(
            "{} references of motion {name}",
            scene.motion(name)?.references.len()
        ),
    };
    let csv = dir.join(csv_name);
    let png = dir.join("sweep.png");
    let table = SweepTable {
        rows,
        reference,
        grid_size: settings.len(),
    };
    let rows = &table.rows;
    stage("write", || -> Result<()> {
        image_io::write_atomic(&csv, table.to_csv().as_bytes())?;
        if args.shard.is_some() {
            return Ok(()); // the front and its plot need every shard: `arlux merge`
        }
        plot(
            rows,
            &format!(
                "{}: {label}, error against time ({} settings)",
                scene.name,
                rows.len()
            ),
            &png,
        )?;
        Ok(())
    })?;
    let plot_file = args.shard.is_none().then_some(png.as_path());
    if as_json {
        return emit(
            "sweep",
            json!({
                "target": label, "settings": rows.len(), "csv": csv.display().to_string(),
                "plot": plot_file.map(|p| p.display().to_string()),
                "rows": rows.iter().map(row_json).collect::<Vec<_>>(),
            }),
        );
    }
    print_front(rows, &label, &csv, plot_file)
}

/// A measured setting for the `--json` report.
fn row_json(r: &arlux::sweep::SweepRow) -> serde_json::Value {
    let s = &r.settings;
    let method = match s.method {
        arlux::sweep::SweepMethod::Pda => json!("pda"),
        arlux::sweep::SweepMethod::Texture { min_leaf_pixels } => {
            json!({ "texture": { "min_leaf_pixels": min_leaf_pixels } })
        }
    };
    json!({
        "method": method,
        "shadow_rays": [1u32 << s.min_level, 1u32 << s.penumbra_level], "supersample": s.supersample,
        "patch_size_m": s.patch_size, "virtual_patch_size_m": matches!(s.method, arlux::sweep::SweepMethod::Pda).then_some(s.virtual_patch_size),
        "epsilon": s.epsilon, "seconds": r.seconds, "rmse": r.rmse,
        "relative_rmse": r.relative_rmse, "pareto": r.pareto,
    })
}

/// What was written, and the Pareto front as a table.
fn print_front(
    rows: &[arlux::sweep::SweepRow],
    label: &str,
    csv: &std::path::Path,
    plot: Option<&std::path::Path>,
) -> Result<()> {
    let mut front: Vec<&arlux::sweep::SweepRow> = rows.iter().filter(|r| r.pareto).collect();
    front.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    say!(
        "{} settings of {label}; wrote {}{}",
        rows.len(),
        csv.display(),
        plot.map_or(String::new(), |p| format!(" and {}", p.display()))
    );
    say!("Pareto front (faster and closer than nothing else):");
    say!(
        "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>9} {:>10}",
        "method",
        "shadow rays",
        "supersamp.",
        "patch",
        "objects",
        "epsilon",
        "seconds",
        "RMSE"
    );
    for r in front {
        let s = &r.settings;
        let (method, rays, supersample) = match s.method {
            arlux::sweep::SweepMethod::Pda => (
                "pda",
                format!("{}-{}", 1u32 << s.min_level, 1u32 << s.penumbra_level),
                s.supersample.to_string(),
            ),
            arlux::sweep::SweepMethod::Texture { min_leaf_pixels } => (
                "texture",
                format!("leaf {min_leaf_pixels} px"),
                "-".to_string(),
            ),
        };
        let objects = match s.method {
            arlux::sweep::SweepMethod::Pda => format!("{} m", s.virtual_patch_size),
            arlux::sweep::SweepMethod::Texture { .. } => "-".to_string(),
        };
        say!(
            "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>9.3} {:>10.6}",
            method,
            rays,
            supersample,
            s.patch_size
                .map_or("auto".to_string(), |m| format!("{m} m")),
            objects,
            s.epsilon,
            r.seconds,
            r.rmse
        );
    }
    Ok(())
}
