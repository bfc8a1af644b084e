//! `arlux sweep`: Error against run time: render a variant (or a motion) over a grid of quality settings, measure each against its reference, and write DIR/sweep.csv and DIR/sweep.png (error against time, Pareto front marked).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};

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
    /// Six pixel-path settings from cheapest to dearest, the defaults with
    /// 4 and 16 rounds of per-pixel samples, and the texture path at its
    /// defaults (nine), for a smoke check.
    #[arg(long)]
    pub quick: bool,
    /// Runs per setting; the fastest counts (default 3, 1 with --quick).
    #[arg(long)]
    pub repeats: Option<usize>,
    /// Run shard i of n (0-based; `auto/n` reads SLURM_ARRAY_TASK_ID or
    /// JOB_COMPLETION_INDEX): a contiguous share of the grid, written to
    /// DIR/sweep.shard-I-of-N.csv; `arlux merge` joins the shards.
    #[arg(long, conflicts_with = "peer")]
    pub shard: Option<String>,
    /// Another renderer on the same axes: LABEL=FILE.csv, where FILE.csv
    /// has the columns seconds,image (images relative to it: renders of
    /// the same variant with their wall times). Repeatable.
    #[arg(long, value_name = "LABEL=FILE.csv")]
    pub peer: Vec<String>,
    /// Run no settings of arlux: measure and plot the peers alone.
    #[arg(long, requires = "peer")]
    pub peer_only: bool,
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
    let (target, label, showing) = match (variant, motion) {
        (_, Some(m)) => (
            Target::Motion { name: m },
            format!("motion {m}"),
            arlux::scene::Showing::Motion(m),
        ),
        (Some(v), None) => (
            Target::Variant { name: v },
            format!("variant {v}"),
            arlux::scene::Showing::Variant(v),
        ),
        (None, None) => bail!("give --variant or --motion"),
    };
    let scene = stage("load", || load_showing(path, showing))?;
    // Known good before the folder is made: a failed run leaves nothing behind.
    let references = arlux::sweep::reference_files(&scene, &target)?;
    if !args.peer.is_empty() && matches!(target, Target::Motion { .. }) {
        bail!("--peer: a peer's CSV holds renders of one variant; give --variant");
    }
    let peers = stage("read peers", || -> Result<Vec<arlux::sweep::Peer>> {
        Ok((args.peer.iter())
            .map(|p| arlux::sweep::read_peer(&scene, p))
            .collect::<arlux::Result<_>>()?)
    })?;
    let settings = match args.peer_only {
        true => Vec::new(),
        false => grid(quick, true),
    };
    let (share, csv_name) = match &args.shard {
        None => (0..settings.len(), "sweep.csv".to_string()),
        Some(text) => {
            let (share, i, n) = shard_range(text, settings.len())?;
            if share.is_empty() {
                // A job array sized for a larger grid: this task has nothing to do
                // (`arlux merge` checks that the shards given cover the grid).
                eprintln!(
                    "note: --shard {text}: no setting falls to shard {i} of {n} ({} in all): nothing run, no table written",
                    settings.len()
                );
                let report = SweepReport {
                    target: label,
                    skill_floor: None,
                    settings: 0,
                    csv: String::new(),
                    plot: None,
                    rows: Vec::new(),
                };
                return print_report(&report, as_json);
            }
            (share, format!("sweep.shard-{i}-of-{n}.csv"))
        }
    };
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: could not create the folder", dir.display()))?;
    let bar = crate::progress::progress_bar(share.len() as u64, "settings");
    let mut rows = stage("renders", || {
        if settings.is_empty() {
            return Ok(Vec::new());
        }
        run(
            &scene,
            &target,
            &settings,
            share.clone(),
            repeats,
            |_, row| {
                bar.set_message(match row.skill {
                    Some(k) => format!("last: {:.2} s, skill {k:.4}", row.seconds),
                    None => format!("last: {:.2} s, RMSE {:.5}", row.seconds, row.rmse),
                });
                bar.inc(1);
            },
        )
    })?;
    bar.finish_and_clear();
    if !peers.is_empty() {
        rows.extend(peer_rows(&scene, &target, &references, &peers)?);
    }
    let reference = reference_label(&scene, &target)?;
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
    let report = SweepReport {
        target: label,
        skill_floor: rows.iter().find_map(|r| r.skill_floor),
        settings: rows.len(),
        csv: csv.display().to_string(),
        plot: args.shard.is_none().then(|| png.display().to_string()),
        rows: rows.iter().map(RowReport::of).collect(),
    };
    print_report(&report, as_json)
}

/// The peers' renders as rows, scored against the variant's reference.
fn peer_rows(
    scene: &arlux::scene::Scene,
    target: &arlux::sweep::Target,
    references: &[std::path::PathBuf],
    peers: &[arlux::sweep::Peer],
) -> Result<Vec<arlux::sweep::SweepRow>> {
    let photo = scene.load_photo()?;
    let reference = scene.fit_size(
        image_io::read_image(&references[0])?,
        "reference",
        &references[0],
    )?;
    let floor = arlux::sweep::skill_floor(scene, target, std::slice::from_ref(&reference), &photo)?;
    Ok(peers
        .iter()
        .flat_map(|p| p.rows(&reference, &photo, floor))
        .collect())
}

/// What the sweep compares against, as the table's header names it.
fn reference_label(scene: &arlux::scene::Scene, target: &arlux::sweep::Target) -> Result<String> {
    use arlux::sweep::Target;
    Ok(match target {
        Target::Variant { name } => scene
            .variant(name)?
            .reference
            .as_ref()
            .map_or(String::new(), |r| rel(scene, r)),
        Target::Motion { name } => format!(
            "{} references of motion {name}",
            scene.motion(name)?.references.len()
        ),
    })
}

/// `arlux sweep`'s report.
#[derive(serde::Serialize)]
struct SweepReport {
    target: String,
    /// The best skill the reference's declared noise allows (null: none declared).
    skill_floor: Option<f64>,
    settings: usize,
    csv: String,
    plot: Option<String>,
    rows: Vec<RowReport>,
}

/// A measured setting.
#[derive(serde::Serialize)]
struct RowReport {
    method: MethodReport,
    /// Shadow rays per light where the samples agree, and in a penumbra.
    shadow_rays: [u32; 2],
    supersample: u32,
    patch_size_m: Option<f64>,
    virtual_patch_size_m: Option<f64>,
    epsilon: f64,
    /// Rounds of per-pixel samples (`--samples`).
    samples: u32,
    seconds: f64,
    rmse: f64,
    relative_rmse: Option<f64>,
    /// Where the change is, as `compare --photo` gives it (a motion: the
    /// mean over its poses).
    skill: Option<f64>,
    rmse_changed: f64,
    n_changed: usize,
    pareto: bool,
}

#[derive(serde::Serialize)]
#[serde(rename_all = "lowercase")]
enum MethodReport {
    Pda,
    Texture { min_leaf_pixels: f64 },
    Peer { label: String },
}

impl RowReport {
    fn of(r: &arlux::sweep::SweepRow) -> Self {
        let s = &r.settings;
        let (method, virtual_patch_size_m) = match s.method {
            arlux::sweep::SweepMethod::Pda => (MethodReport::Pda, Some(s.virtual_patch_size)),
            arlux::sweep::SweepMethod::Texture { min_leaf_pixels } => {
                (MethodReport::Texture { min_leaf_pixels }, None)
            }
            arlux::sweep::SweepMethod::Peer => (
                MethodReport::Peer {
                    label: r.peer.clone().unwrap_or_default(),
                },
                None,
            ),
        };
        RowReport {
            method,
            shadow_rays: [1u32 << s.min_level, 1u32 << s.penumbra_level],
            supersample: s.supersample,
            patch_size_m: s.patch_size,
            virtual_patch_size_m,
            epsilon: s.epsilon,
            samples: s.samples,
            seconds: r.seconds,
            rmse: r.rmse,
            relative_rmse: r.relative_rmse,
            skill: r.skill,
            rmse_changed: r.rmse_changed,
            n_changed: r.n_changed,
            pareto: r.pareto,
        }
    }
}

impl Report for SweepReport {
    const COMMAND: &'static str = "sweep";

    /// What was written, and the Pareto front as a table.
    fn text(&self) -> Vec<String> {
        let mut front: Vec<&RowReport> = self.rows.iter().filter(|r| r.pareto).collect();
        front.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        let mut lines = vec![
            format!(
                "{} settings of {}; wrote {}{}",
                self.settings,
                self.target,
                self.csv,
                self.plot
                    .as_ref()
                    .map_or(String::new(), |p| format!(" and {p}"))
            ),
            "Pareto front (nothing else both faster and closer where the change is):".to_string(),
            format!(
                "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>7} {:>9} {:>10} {:>7}",
                "method",
                "shadow rays",
                "supersamp.",
                "patch",
                "objects",
                "epsilon",
                "samples",
                "seconds",
                "RMSE",
                "skill"
            ),
        ];
        for r in front {
            let (method, rays, supersample, objects) = match (&r.method, r.virtual_patch_size_m) {
                (MethodReport::Texture { min_leaf_pixels }, _) => (
                    "texture",
                    format!("leaf {min_leaf_pixels} px"),
                    "-".to_string(),
                    "-".to_string(),
                ),
                (MethodReport::Pda, objects) => (
                    "pda",
                    format!("{}-{}", r.shadow_rays[0], r.shadow_rays[1]),
                    r.supersample.to_string(),
                    objects.map_or("-".to_string(), |m| format!("{m} m")),
                ),
                // Never on the front: listed below.
                (MethodReport::Peer { .. }, _) => continue,
            };
            lines.push(format!(
                "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>7} {:>9.3} {:>10.6} {:>7}",
                method,
                rays,
                supersample,
                r.patch_size_m
                    .map_or("auto".to_string(), |m| format!("{m} m")),
                objects,
                r.epsilon,
                r.samples,
                r.seconds,
                r.rmse,
                r.skill.map_or("-".to_string(), |k| format!("{k:.4}"))
            ));
        }
        for r in &self.rows {
            if let MethodReport::Peer { label } = &r.method {
                lines.push(format!(
                    "peer {label}: {:.3} s, RMSE {:.6}, skill {}",
                    r.seconds,
                    r.rmse,
                    r.skill.map_or("-".to_string(), |k| format!("{k:.4}"))
                ));
            }
        }
        if let Some(f) = self.skill_floor {
            lines.push(format!(
                "the reference's own noise allows a skill of {f:.4} at best"
            ));
        }
        lines
    }
}
