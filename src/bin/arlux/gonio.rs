//! `arlux gonio`: Recover the goniometric of the scene's light marked intensity = "reconstruct" from the photo (Grosch §2.3), with the reflectances it needs on the way; writes it as an IES LM-63 file.

use std::path::PathBuf;

use anyhow::{Result, bail};

use arlux::image_io::{self};

use arlux::gonio::ReflectanceSource;

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux gonio`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    /// Output IES file (candela relative to the printed rgb).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also a polar plot PNG of the recovered distribution.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Spacing of the table's vertical angles, degrees.
    #[arg(long, default_value_t = 1.0)]
    pub vertical_step: f64,
    /// Spacing of its horizontal angles, degrees.
    #[arg(long, default_value_t = 2.5)]
    pub horizontal_step: f64,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let path = args.scene.as_path();
    let output = args.output.as_path();
    let plot = args.plot.as_deref();
    let vertical_step = args.vertical_step;
    let horizontal_step = args.horizontal_step;
    let as_json = args.json;
    use arlux::gonio::{GonioSettings, reconstruct};
    let settings = GonioSettings {
        vertical_step_deg: vertical_step,
        horizontal_step_deg: horizontal_step,
        ..GonioSettings::default()
    };
    settings.validate()?;
    let mut times = arlux::model::StageTimes::default();
    let scene = times.time("load", || load(path, None))?;
    if arlux::gonio::light_to_reconstruct(&scene)?.is_none() {
        bail!(
            "{}: no light has intensity = \"reconstruct\"",
            path.display()
        );
    }
    let tracer = times.time("tracer", || arlux::scene_tracer::build_tracer(&scene))?;
    let photo = photo_in_units(
        &scene,
        &tracer,
        &arlux::model::ModelSettings::default(),
        &mut times,
    )?;
    let rec = times.time("reconstruct", || {
        reconstruct(&scene, &photo, &tracer, &settings)
    })?;
    times.time("write", || -> Result<()> {
        image_io::write_atomic(output, rec.profile.to_lm63().as_bytes())?;
        if let Some(plot) = plot {
            let (w, h, rgb) =
                arlux::gonio::polar_plot(&rec).map_err(|m| arlux::Error::file(plot, m))?;
            image_io::write_png_rgb8(plot, w, h, rgb)?;
        }
        Ok(())
    })?;
    keep(&times);
    let report = GonioReport::new(&rec, &scene.lights[rec.light].name, output, &times);
    print_report(&report, as_json)
}

/// `arlux gonio`'s report.
#[derive(serde::Serialize)]
struct GonioReport {
    light: String,
    position: [f64; 3],
    rgb: [f64; 3],
    peak_candela: f64,
    peak_direction: [f64; 3],
    /// The share of the sphere the photo tells.
    coverage: f64,
    colour_residual: f64,
    rounds: usize,
    last_change: f64,
    samples: usize,
    patches: usize,
    reconstruction_seconds: f64,
    paper_seconds: f64,
    reflectances: Vec<SurfaceReport>,
    output: String,
    stages: serde_json::Value,
    seconds: f64,
}

/// A surface's reflectance and where it came from.
#[derive(serde::Serialize)]
struct SurfaceReport {
    surface: String,
    rgb: Option<[f64; 3]>,
    source: &'static str,
    /// For EQ2: its step, the widest angle to a known direction, and the pixels read.
    step: Option<usize>,
    angle_deg: Option<f64>,
    samples: Option<usize>,
}

impl GonioReport {
    fn new(
        rec: &arlux::gonio::Reconstruction,
        light: &str,
        output: &std::path::Path,
        times: &arlux::model::StageTimes,
    ) -> Self {
        let (peak, peak_dir) = arlux::gonio::peak(rec);
        let reflectances = rec
            .reflectances
            .iter()
            .map(|r| {
                let (source, step, angle_deg, samples) = match r.source {
                    ReflectanceSource::Known => ("known", None, None, None),
                    ReflectanceSource::Propagated {
                        step,
                        angle_deg,
                        samples,
                    } => ("EQ2", Some(step), Some(angle_deg), Some(samples)),
                    ReflectanceSource::Unreached => ("unreached", None, None, None),
                };
                SurfaceReport {
                    surface: r.name.clone(),
                    rgb: r.rgb.map(|c| c.to_array()),
                    source,
                    step,
                    angle_deg,
                    samples,
                }
            })
            .collect();
        GonioReport {
            light: light.to_string(),
            position: rec.position.to_array(),
            rgb: rec.colour.to_array(),
            peak_candela: peak,
            peak_direction: peak_dir.to_array(),
            coverage: rec.coverage,
            colour_residual: rec.colour_residual,
            rounds: rec.rounds,
            last_change: rec.change,
            samples: rec.samples,
            patches: rec.patches,
            reconstruction_seconds: rec.seconds,
            paper_seconds: 97.9,
            reflectances,
            output: output.display().to_string(),
            stages: stages_json(times),
            seconds: times.total().as_secs_f64(),
        }
    }
}

impl Report for GonioReport {
    const COMMAND: &'static str = "gonio";

    /// The reconstruction, with the line that uses the file written.
    fn text(&self) -> Vec<String> {
        let v = |a: [f64; 3]| fmt3(glam::DVec3::from_array(a));
        let mut lines = vec![
            format!(
                "light '{}' at {}: reconstructed from {} pixels ({} patches for the indirect light), {} rounds (last change {:.1e} of the peak)",
                self.light,
                v(self.position),
                self.samples,
                self.patches,
                self.rounds,
                self.last_change
            ),
            format!(
                "peak {:.3} × rgb {} towards {}; {:.1}% of the sphere is known from the photo (the rest is 0 and marked unknown)",
                self.peak_candela,
                v(self.rgb),
                v(self.peak_direction),
                100.0 * self.coverage
            ),
        ];
        for r in &self.reflectances {
            let rgb = r.rgb.map_or("-".to_string(), |c| {
                format!("[{:.3}, {:.3}, {:.3}]", c[0], c[1], c[2])
            });
            lines.push(match (r.source, r.step, r.angle_deg, r.samples) {
                ("EQ2", Some(step), Some(angle_deg), Some(samples)) => format!(
                    "  {:<14} {rgb}  EQ2 step {step}, from directions within {angle_deg:.2}° ({samples} pixels)",
                    r.surface
                ),
                ("known", ..) => format!("  {:<14} {rgb}  known", r.surface),
                _ => format!(
                    "  {:<14} -  not lit by this light where the photo sees it",
                    r.surface
                ),
            });
        }
        lines.push(format!(
            "reconstruction {:.2} s (Grosch et al.: {} s for 282 patches); total {:.2} s",
            self.reconstruction_seconds, self.paper_seconds, self.seconds
        ));
        let c = self.rgb;
        lines.push(format!(
            "wrote {}; use it as: intensity = {{ ies = \"{}\", rgb = [{:.4}, {:.4}, {:.4}], direction = [0.0, -1.0, 0.0], reference = [1.0, 0.0, 0.0] }}",
            self.output, self.output, c[0], c[1], c[2]
        ));
        lines
    }
}

// One argument per command-line flag.
