//! `arlux hdr`: Merge 8-bit exposure brackets into an HDR radiance map (Debevec & Malik): the camera response per channel, then a weighted merge. Radiance is relative (the base exposure time is unknown).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use arlux::image_io::{self};

use crate::timing::*;

/// Arguments of `arlux hdr`.
#[derive(clap::Args)]
pub struct Args {
    /// An exposure as IMAGE:EV, e.g. brackets/ev-2.png:-2 (at least two).
    #[arg(long = "bracket", required = true)]
    pub brackets: Vec<String>,
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the recovered response as CSV (code, then ln exposure per channel).
    #[arg(long)]
    pub response: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let brackets = &args.brackets;
    let output = args.output.as_path();
    let response_csv = args.response.as_deref();
    use arlux::hdr::{Exposure, merge, recover_response};
    let mut exposures = Vec::new();
    for b in brackets {
        let Some((path, ev)) = b.rsplit_once(':') else {
            bail!("--bracket {b}: give IMAGE:EV, e.g. ev-2.png:-2");
        };
        let ev: f64 = ev
            .trim()
            .parse()
            .map_err(|_| anyhow::anyhow!("--bracket {b}: '{ev}' is not an EV number"))?;
        if !ev.is_finite() {
            bail!("--bracket {b}: the EV must be finite");
        }
        exposures.push(stage("load", || Exposure::read(Path::new(path), ev))?);
    }
    let response = stage("response", || recover_response(&exposures, 64, 20.0))?;
    let merged = stage("merge", || merge(&exposures, &response))?;
    stage("write", || -> Result<()> {
        image_io::write_exr(
            output,
            merged.image.width,
            merged.image.height,
            &[image_io::ExrLayer::Rgb("", &merged.image)],
        )?;
        if let Some(csv) = response_csv {
            let mut text = String::from("code,ln_exposure_r,ln_exposure_g,ln_exposure_b\n");
            for (z, ((r, g), b)) in response[0]
                .iter()
                .zip(&response[1])
                .zip(&response[2])
                .enumerate()
            {
                text.push_str(&format!("{z},{r},{g},{b}\n"));
            }
            image_io::write_atomic(csv, text.as_bytes())?;
        }
        Ok(())
    })?;
    let report = HdrReport {
        exposures: exposures.len(),
        output: output.display().to_string(),
        width: merged.image.width,
        height: merged.image.height,
        saturated_pixels: merged.saturated.iter().filter(|s| **s).count(),
        black_pixels: merged.black.iter().filter(|s| **s).count(),
        relative_radiance: true,
    };
    crate::common::print_report(&report, args.json)
}

/// `arlux hdr`'s report.
#[derive(serde::Serialize)]
struct HdrReport {
    exposures: usize,
    output: String,
    width: u32,
    height: u32,
    /// Pixels saturated, or black, in every exposure.
    saturated_pixels: usize,
    black_pixels: usize,
    /// The merge's radiance is relative: the base exposure time is unknown.
    relative_radiance: bool,
}

impl crate::common::Report for HdrReport {
    const COMMAND: &'static str = "hdr";

    fn text(&self) -> Vec<String> {
        vec![format!(
            "merged {} exposures into {} ({}x{}); {} pixels saturated in every exposure, {} black in every exposure; radiance is relative (g(128) = 0, t0 = 1)",
            self.exposures,
            self.output,
            self.width,
            self.height,
            self.saturated_pixels,
            self.black_pixels
        )]
    }
}
