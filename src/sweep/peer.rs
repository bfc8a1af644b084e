//! A peer on the sweep's axes: another renderer's images of the same
//! variant (a path tracer at growing sample counts) with their wall
//! times, from a CSV of `seconds,image`, measured as arlux's own renders
//! are. The CSV is small and fixed (two columns, no quoting), so it is
//! split by hand rather than through a CSV crate.

use std::path::{Path, PathBuf};

use super::{SweepMethod, SweepRow, SweepSettings};
use crate::compare::{compare, skill};
use crate::error::{Error, Result};
use crate::image_io::{Image, read_image};
use crate::scene::Scene;

/// A peer's renders, read and checked.
#[derive(Debug, Clone)]
pub struct Peer {
    /// Its name on the plot and in the CSV's `method` column.
    pub label: String,
    pub file: PathBuf,
    /// Per CSV row: the wall time and the image.
    pub renders: Vec<(f64, Image)>,
}

/// Reads `spec` (`LABEL=FILE.csv`) and every image its CSV names, each
/// checked to be the camera's size: an error names the CSV and its line.
pub fn read_peer(scene: &Scene, spec: &str) -> Result<Peer> {
    let Some((label, file)) = spec.split_once('=') else {
        return Err(Error::file(
            spec,
            "a peer is LABEL=FILE.csv (FILE.csv has the columns seconds,image)",
        ));
    };
    let file = PathBuf::from(file);
    if label.is_empty() || label.contains([',', '"', '\n']) || ["pda", "texture"].contains(&label) {
        return Err(Error::file(
            &file,
            format!(
                "peer label '{label}': give a name without commas or quotes, not pda or texture"
            ),
        ));
    }
    let text = std::fs::read_to_string(&file).map_err(|e| Error::io(&file, &e))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let header: Vec<&str> = match lines.next() {
        Some((_, h)) => h.split(',').map(str::trim).collect(),
        None => {
            return Err(Error::line(
                &file,
                1,
                "empty: the header seconds,image first",
            ));
        }
    };
    let (Some(at_seconds), Some(at_image)) = (
        header.iter().position(|h| *h == "seconds"),
        header.iter().position(|h| *h == "image"),
    ) else {
        return Err(Error::line(
            &file,
            1,
            format!("header {header:?}: needs the columns seconds and image"),
        ));
    };
    let dir = file.parent().unwrap_or(Path::new("")).to_path_buf();
    let mut renders = Vec::new();
    for (k, line) in lines {
        let at = |m: String| Error::line(&file, k + 1, m);
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != header.len() {
            return Err(at(format!(
                "{} cells, the header has {}",
                cells.len(),
                header.len()
            )));
        }
        let seconds: f64 = (cells[at_seconds].parse().ok())
            .filter(|s: &f64| s.is_finite() && *s > 0.0)
            .ok_or_else(|| {
                at(format!(
                    "seconds '{}': give a positive number",
                    cells[at_seconds]
                ))
            })?;
        let path = dir.join(cells[at_image]);
        let image = read_image(&path)
            .and_then(|i| scene.fit_size(i, "image", &path))
            .map_err(|e| at(format!("image {}: {e}", path.display())))?;
        renders.push((seconds, image));
    }
    if renders.is_empty() {
        return Err(Error::line(&file, 2, "no renders: one row per image"));
    }
    Ok(Peer {
        label: label.to_string(),
        file,
        renders,
    })
}

impl Peer {
    /// Its renders measured against `reference`, as the sweep measures
    /// its own ([`crate::compare::skill`] over the photo), as rows.
    pub fn rows(&self, reference: &Image, photo: &Image, floor: Option<f64>) -> Vec<SweepRow> {
        (self.renders.iter().enumerate())
            .map(|(i, (seconds, image))| {
                let c = compare(image, reference, None);
                let s = skill(image, reference, photo);
                SweepRow {
                    index: i,
                    settings: SweepSettings {
                        method: SweepMethod::Peer,
                        ..SweepSettings::defaults()
                    },
                    peer: Some(self.label.clone()),
                    stages: Vec::new(),
                    seconds: *seconds,
                    seconds_median: *seconds,
                    seconds_max: *seconds,
                    rmse: c.rmse,
                    relative_rmse: c.relative_rmse,
                    psnr_srgb_db: c.psnr_srgb_db,
                    compared: 1,
                    skill: s.skill,
                    rmse_changed: s.rmse_changed,
                    n_changed: s.changed_pixels,
                    skill_floor: floor,
                    pareto: false,
                }
            })
            .collect()
    }
}
