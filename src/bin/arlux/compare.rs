//! `arlux compare`: Error of an image against a reference: RMSE and relative RMSE in linear radiance, PSNR of the sRGB-encoded images, and their means.

use std::path::PathBuf;

use anyhow::{Result, bail};

use arlux::compare::{Comparison, compare, read_mask, skill};
use arlux::image_io::{self, Image};

use crate::common::{Report, print_report, skill_line};
use crate::timing::*;

/// Arguments of `arlux compare`.
#[derive(clap::Args)]
pub struct Args {
    pub image: PathBuf,
    pub reference: PathBuf,
    /// Compare only where this PNG is white (grey > 0.5).
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// The photo the image changed: also report the skill over the pixels
    /// the change from the photo to the reference touches (1 perfect, 0 no
    /// better than the photo, negative worse).
    #[arg(long)]
    pub photo: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let image = args.image.as_path();
    let reference = args.reference.as_path();
    let mask = args.mask.as_deref();
    let as_json = args.json;
    let (a, b, photo) = stage("load", || -> Result<(Image, Image, Option<Image>)> {
        let photo = args
            .photo
            .as_deref()
            .map(image_io::read_image)
            .transpose()?;
        Ok((
            image_io::read_image(image)?,
            image_io::read_image(reference)?,
            photo,
        ))
    })?;
    let others = [(reference, &b)]
        .into_iter()
        .chain(args.photo.as_deref().zip(photo.as_ref()));
    for (path, other) in others {
        if (a.width, a.height) != (other.width, other.height) {
            bail!(arlux::Error::file(
                image,
                format!(
                    "is {}x{} but {} is {}x{}",
                    a.width,
                    a.height,
                    path.display(),
                    other.width,
                    other.height
                )
            ));
        }
    }
    let mask = mask.map(|m| read_mask(m, a.width, a.height)).transpose()?;
    let c: Comparison = stage("compare", || compare(&a, &b, mask.as_deref()));
    let s = photo.map(|p| stage("skill", || skill(&a, &b, &p)));
    print_report(
        &CompareReport {
            comparison: c,
            skill: s,
        },
        as_json,
    )
}

/// `arlux compare`'s report.
#[derive(serde::Serialize)]
struct CompareReport {
    comparison: Comparison,
    /// With `--photo`: the skill over the pixels the change touches.
    skill: Option<arlux::compare::Skill>,
}

impl Report for CompareReport {
    const COMMAND: &'static str = "compare";

    fn text(&self) -> Vec<String> {
        let c = &self.comparison;
        let mut lines = vec![
            format!("pixels         {}", c.pixels),
            format!("rmse           {:.6}", c.rmse),
            format!(
                "relative rmse  {}",
                c.relative_rmse
                    .map_or("n/a (black reference)".into(), |r| format!("{:.4}", r))
            ),
            format!(
                "psnr (sRGB)    {}",
                c.psnr_srgb_db
                    .map_or("inf (identical)".into(), |p| format!("{p:.2} dB"))
            ),
            format!("mean           {:.6}", c.mean),
            format!("mean reference {:.6}", c.mean_reference),
        ];
        lines.extend(self.skill.as_ref().map(skill_line));
        lines
    }
}
