//! A sweep's rows as CSV, read back, and the CSVs of a sweep's shards
//! merged into the whole sweep's. The format is small and fixed, so it is
//! written and split by hand rather than through a CSV crate: no field
//! holds a comma or a quote but the reference's name, which is checked.

use super::{SweepMethod, SweepRow, SweepSettings, mark_pareto};
use crate::error::{Error, Result};

/// A sweep's table: its rows (in grid order), what they were measured
/// against, and the size of the whole grid.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepTable {
    pub rows: Vec<SweepRow>,
    pub reference: String,
    pub grid_size: usize,
}

const SETTINGS: &str = "setting,grid_size,method,min_level,penumbra_level,shadow_rays_min,shadow_rays_max,supersample,min_leaf_pixels,patch_size,virtual_patch_size,epsilon,samples";
const FIGURES: &str = "total_seconds,seconds_median,seconds_max,rmse,relative_rmse,psnr_srgb_db,skill,rmse_changed,n_changed,skill_floor,images_compared,reference,pareto";

/// A stage's name as a column: `s_` and the name's words joined by
/// underscores (`estimate + solve` → `s_estimate_solve`).
fn stage_column(name: &str) -> String {
    let words: Vec<&str> = name
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    format!("s_{}", words.join("_"))
}

impl SweepTable {
    /// The rows as CSV: the setting's index in the grid and the grid's
    /// size, the settings, seconds per stage (the union of stages, in
    /// first-seen order), total seconds, error figures (empty where
    /// undefined), Pareto flag.
    pub fn to_csv(&self) -> String {
        let mut names: Vec<String> = Vec::new();
        for r in &self.rows {
            for (n, _) in &r.stages {
                if !names.contains(n) {
                    names.push(n.clone());
                }
            }
        }
        let mut out = String::from(SETTINGS);
        for n in &names {
            out.push(',');
            out.push_str(&stage_column(n));
        }
        out.push(',');
        out.push_str(FIGURES);
        out.push('\n');
        for r in &self.rows {
            let s = &r.settings;
            let patch = s.patch_size.map_or("auto".to_string(), |m| m.to_string());
            out.push_str(&format!("{},{},", r.index, self.grid_size));
            out.push_str(&match s.method {
                SweepMethod::Pda => format!(
                    "pda,{},{},{},{},{},,{patch},{},{},{}",
                    s.min_level,
                    s.penumbra_level,
                    1u32 << s.min_level,
                    1u32 << s.penumbra_level,
                    s.supersample,
                    s.virtual_patch_size,
                    s.epsilon,
                    s.samples
                ),
                // Shadow rays and supersampling do not apply: its leaves take 2^4 rays per point.
                SweepMethod::Texture { min_leaf_pixels } => {
                    format!("texture,,,,,,{min_leaf_pixels},{patch},,{},", s.epsilon)
                }
                // Its label, checked to hold no comma or quote.
                SweepMethod::Peer => format!("{},,,,,,,,,,", r.peer.as_deref().unwrap_or("peer")),
            });
            for n in &names {
                let v = r.stages.iter().find(|(m, _)| m == n).map_or(0.0, |x| x.1);
                out.push_str(&format!(",{v:.6}"));
            }
            let cell = |v: Option<f64>, digits: usize| {
                v.map_or(String::new(), |v| format!("{v:.digits$}"))
            };
            out.push_str(&format!(
                ",{:.6},{:.6},{:.6},{:.8},{},{},{},{:.8},{},{},{},{},{}\n",
                r.seconds,
                r.seconds_median,
                r.seconds_max,
                r.rmse,
                cell(r.relative_rmse, 8),
                cell(r.psnr_srgb_db, 4),
                cell(r.skill, 6),
                r.rmse_changed,
                r.n_changed,
                cell(r.skill_floor, 6),
                r.compared,
                self.reference,
                r.pareto as u8
            ));
        }
        out
    }

    /// Reads a table [`SweepTable::to_csv`] wrote; `file` names it in errors.
    pub fn from_csv(text: &str, file: &std::path::Path) -> Result<SweepTable> {
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
        let fixed: Vec<&str> = SETTINGS.split(',').collect();
        let tail: Vec<&str> = FIGURES.split(',').collect();
        let n = header.len();
        if n < fixed.len() + tail.len()
            || header[..fixed.len()] != fixed[..]
            || header[n - tail.len()..] != tail[..]
        {
            return Err(Error::line(
                file,
                1,
                "not the header of an arlux sweep's table",
            ));
        }
        let stages: Vec<String> = header[fixed.len()..n - tail.len()]
            .iter()
            .map(|c| c.trim_start_matches("s_").to_string())
            .collect();
        let mut table = SweepTable {
            rows: Vec::new(),
            reference: String::new(),
            grid_size: 0,
        };
        for (k, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
            let at = |m: String| Error::line(file, k + 2, m);
            let cells: Vec<&str> = line.split(',').collect();
            if cells.len() != n {
                return Err(at(format!("{} cells, the header has {n}", cells.len())));
            }
            let row = parse_row(&cells, &stages, &mut table).map_err(at)?;
            table.rows.push(row);
        }
        Ok(table)
    }
}

/// One CSV row; sets the table's reference and grid size from it.
fn parse_row(
    cells: &[&str],
    stages: &[String],
    table: &mut SweepTable,
) -> std::result::Result<SweepRow, String> {
    let num = |i: usize| -> std::result::Result<f64, String> {
        cells[i]
            .parse::<f64>()
            .map_err(|_| format!("column {} is '{}', not a number", i + 1, cells[i]))
    };
    let opt = |i: usize| -> std::result::Result<Option<f64>, String> {
        if cells[i].is_empty() {
            Ok(None)
        } else {
            num(i).map(Some)
        }
    };
    let d = SweepSettings::defaults();
    let (method, peer) = match cells[2] {
        "pda" => (SweepMethod::Pda, None),
        "texture" => (
            SweepMethod::Texture {
                min_leaf_pixels: num(8)?,
            },
            None,
        ),
        "" => return Err("no method".to_string()),
        label => (SweepMethod::Peer, Some(label.to_string())),
    };
    // The figures, the same columns for every row.
    let f = cells.len() - 13;
    let mut row = SweepRow {
        index: num(0)? as usize,
        settings: SweepSettings { method, ..d },
        peer: None,
        stages: Vec::new(),
        seconds: num(f)?,
        seconds_median: num(f + 1)?,
        seconds_max: num(f + 2)?,
        rmse: num(f + 3)?,
        relative_rmse: opt(f + 4)?,
        psnr_srgb_db: opt(f + 5)?,
        skill: opt(f + 6)?,
        rmse_changed: num(f + 7)?,
        n_changed: num(f + 8)? as usize,
        skill_floor: opt(f + 9)?,
        compared: num(f + 10)? as usize,
        pareto: cells[f + 12] == "1",
    };
    if peer.is_some() {
        // Never on arlux's front; no settings.
        return Ok(SweepRow {
            peer,
            pareto: false,
            ..row
        });
    }
    let pda = method == SweepMethod::Pda;
    row.settings = SweepSettings {
        method,
        min_level: if pda { num(3)? as usize } else { d.min_level },
        penumbra_level: if pda {
            num(4)? as usize
        } else {
            d.penumbra_level
        },
        supersample: if pda { num(7)? as u32 } else { 1 },
        patch_size: if cells[9] == "auto" {
            None
        } else {
            Some(num(9)?)
        },
        virtual_patch_size: if pda { num(10)? } else { d.virtual_patch_size },
        epsilon: num(11)?,
        samples: if pda { num(12)? as u32 } else { 0 },
    };
    row.stages = (stages.iter().enumerate())
        .map(|(j, s)| Ok((s.clone(), num(13 + j)?)))
        .collect::<std::result::Result<_, String>>()?;
    table.reference = cells[f + 11].to_string();
    table.grid_size = num(1)? as usize;
    Ok(row)
}

/// The tables of a sweep's shards as the whole sweep's: rows in grid
/// order, the Pareto front marked over all of them. Every shard must come
/// from one sweep (same grid size and reference), and together they must
/// hold each setting of the grid once.
pub fn merge_tables(shards: &[(std::path::PathBuf, SweepTable)]) -> Result<SweepTable> {
    let Some((first_file, first)) = shards.first() else {
        return Err(Error::file("-", "no sweep tables to merge"));
    };
    let mut rows: Vec<SweepRow> = Vec::new();
    let mut from: Vec<Option<&std::path::Path>> = vec![None; first.grid_size];
    for (file, t) in shards {
        if (t.grid_size, &t.reference) != (first.grid_size, &first.reference) {
            return Err(Error::file(
                file,
                format!(
                    "from another sweep than {} (grid of {} against {}, reference '{}' against '{}')",
                    first_file.display(),
                    t.grid_size,
                    first.grid_size,
                    t.reference,
                    first.reference
                ),
            ));
        }
        for r in &t.rows {
            match from.get_mut(r.index) {
                None => {
                    return Err(Error::file(
                        file,
                        format!(
                            "setting {} lies outside the grid of {}",
                            r.index, t.grid_size
                        ),
                    ));
                }
                Some(Some(other)) => {
                    return Err(Error::file(
                        file,
                        format!("setting {} is also in {}", r.index, other.display()),
                    ));
                }
                Some(slot) => *slot = Some(file),
            }
            rows.push(r.clone());
        }
    }
    if let Some(i) = from.iter().position(Option::is_none) {
        let missing = from.iter().filter(|f| f.is_none()).count();
        return Err(Error::file(
            first_file,
            format!(
                "the shards leave {missing} of {} settings out, the first {i}: give every shard",
                first.grid_size
            ),
        ));
    }
    rows.sort_by_key(|r| r.index);
    mark_pareto(&mut rows);
    Ok(SweepTable {
        rows,
        reference: first.reference.clone(),
        grid_size: first.grid_size,
    })
}
