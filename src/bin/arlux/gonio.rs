//! `arlux gonio`: Recover the goniometric of the scene's light marked intensity = "reconstruct" from the photo (Grosch §2.3), with the reflectances it needs on the way; writes it as an IES LM-63 file.

use std::path::PathBuf;

use anyhow::{Result, bail};
use serde_json::json;

use arlux::image_io::{self};

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
    use arlux::gonio::{GonioSettings, ReflectanceSource, reconstruct};
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
    let photo = photo_in_units(&scene, &tracer, &mut times)?;
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
    let light = &scene.lights[rec.light];
    let (peak, peak_dir) = arlux::gonio::peak(&rec);
    let surfaces: Vec<_> = rec
        .reflectances
        .iter()
        .map(|r| {
            let (source, step, angle) = match r.source {
                ReflectanceSource::Known => ("known", None, None),
                ReflectanceSource::Propagated { step, angle_deg, .. } => ("EQ2", Some(step), Some(angle_deg)),
                ReflectanceSource::Unreached => ("unreached", None, None),
            };
            json!({ "surface": r.name, "rgb": r.rgb.map(|c| c.to_array()), "source": source, "step": step, "angle_deg": angle })
        })
        .collect();
    keep(&times);
    let report = json!({
        "light": light.name,
        "position": rec.position.to_array(),
        "rgb": rec.colour.to_array(),
        "peak_candela": peak,
        "peak_direction": peak_dir.to_array(),
        "coverage": rec.coverage,
        "colour_residual": rec.colour_residual,
        "rounds": rec.rounds,
        "last_change": rec.change,
        "samples": rec.samples,
        "patches": rec.patches,
        "reconstruction_seconds": rec.seconds,
        "paper_seconds": 97.9,
        "reflectances": surfaces,
        "output": output.display().to_string(),
        "stages": stages_json(&times),
        "seconds": times.total().as_secs_f64(),
    });
    if as_json {
        return emit("gonio", report);
    }
    print_reconstruction(&rec, &light.name, output, times.total().as_secs_f64())
}

/// The reconstruction as text, with the line that uses the file written.
fn print_reconstruction(
    rec: &arlux::gonio::Reconstruction,
    light: &str,
    output: &std::path::Path,
    seconds: f64,
) -> Result<()> {
    use arlux::gonio::ReflectanceSource;
    let (peak, peak_dir) = arlux::gonio::peak(rec);
    say!(
        "light '{}' at {}: reconstructed from {} pixels ({} patches for the indirect light), {} rounds (last change {:.1e} of the peak)",
        light,
        fmt3(rec.position),
        rec.samples,
        rec.patches,
        rec.rounds,
        rec.change
    );
    say!(
        "peak {:.3} × rgb {} towards {}; {:.1}% of the sphere is known from the photo (the rest is 0 and marked unknown)",
        peak,
        fmt3(rec.colour),
        fmt3(peak_dir),
        100.0 * rec.coverage
    );
    for r in &rec.reflectances {
        let rgb = r.rgb.map_or("-".to_string(), |c| {
            format!("[{:.3}, {:.3}, {:.3}]", c.x, c.y, c.z)
        });
        match r.source {
            ReflectanceSource::Known => say!("  {:<14} {rgb}  known", r.name),
            ReflectanceSource::Propagated {
                step,
                angle_deg,
                samples,
            } => {
                say!(
                    "  {:<14} {rgb}  EQ2 step {step}, from directions within {angle_deg:.2}° ({samples} pixels)",
                    r.name
                )
            }
            ReflectanceSource::Unreached => say!(
                "  {:<14} -  not lit by this light where the photo sees it",
                r.name
            ),
        }
    }
    say!(
        "reconstruction {:.2} s (Grosch et al.: 97.9 s for 282 patches); total {:.2} s",
        rec.seconds,
        seconds
    );
    say!(
        "wrote {}; use it as: intensity = {{ ies = \"{}\", rgb = [{:.4}, {:.4}, {:.4}], direction = [0.0, -1.0, 0.0], reference = [1.0, 0.0, 0.0] }}",
        output.display(),
        output.display(),
        rec.colour.x,
        rec.colour.y,
        rec.colour.z
    );
    Ok(())
}

// One argument per command-line flag.
