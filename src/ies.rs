//! [`IesProfile`]: IES LM-63 photometric files (1986/1991/1995/2002/2019):
//! parsed, evaluated with bilinear interpolation in the two angles, and
//! written back so that a profile round-trips.
//!
//! Accepted: TILT=NONE, TILT=INCLUDE and `TILT=<file>`; photometric types C, B
//! and A; the horizontal symmetries 0, 0-90, 0-180, 90-270 and 0-360 (type
//! C) or 0-90 and -90-90 (types A, B); keyword lines with or without a space
//! after the bracket; values split across lines in any way, separated by
//! spaces or commas. A malformed file is an error with its line number.
//!
//! Angles: type C, vertical 0 is photometric zero (nadir) and horizontal
//! angles turn about it; types B and A, horizontal angles turn about the
//! photometric horizontal axis (B) or the vertical axis (A), as LM-63-2002
//! defines them. [`IesProfile::candela`] takes the file's own angles;
//! [`IesProfile::candela_towards`] takes a direction in the luminaire frame.

use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;

use crate::error::{Error, Result};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PhotometricType {
    C = 1,
    B = 2,
    A = 3,
}

/// Lamp output against the luminaire's tilt, when the file gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct Tilt {
    /// 1: lamp vertical; 2: horizontal along the 0-180 plane; 3: along 90-270.
    pub lamp_geometry: u32,
    pub angles: Vec<f64>,
    pub factors: Vec<f64>,
}

impl Tilt {
    /// The multiplying factor at `angle_deg`, interpolated linearly and held
    /// constant beyond the table.
    pub fn factor(&self, angle_deg: f64) -> f64 {
        interpolate_1d(&self.angles, &self.factors, angle_deg)
    }
}

/// One IES LM-63 luminaire data set.
#[derive(Debug, Clone, PartialEq)]
pub struct IesProfile {
    /// The version line (`IESNA:LM-63-2002`, ...), empty for 1986 files.
    pub version: String,
    /// Keyword lines, `[KEY] value`, and any other label lines (as `("", line)`).
    pub keywords: Vec<(String, String)>,
    pub tilt: Option<Tilt>,
    pub lamps: u32,
    /// -1 for absolute photometry.
    pub lumens_per_lamp: f64,
    pub multiplier: f64,
    pub photometric_type: PhotometricType,
    /// 1: feet, 2: metres.
    pub units: u32,
    pub width: f64,
    pub length: f64,
    pub height: f64,
    pub ballast_factor: f64,
    /// "Future use" in LM-63-2002 (ballast-lamp photometric factor before); normally 1.
    pub ballast_lamp_factor: f64,
    pub input_watts: f64,
    pub vertical: Vec<f64>,
    pub horizontal: Vec<f64>,
    /// Candela values, for each horizontal angle all the vertical angles.
    pub candela: Vec<f64>,
}

/// A number with the line it stood on.
struct Token<'a> {
    text: &'a str,
    line: usize,
}

struct Tokens<'a> {
    path: &'a Path,
    tokens: Vec<Token<'a>>,
    next: usize,
    last_line: usize,
}

impl<'a> Tokens<'a> {
    fn new(path: &'a Path, lines: &[(usize, &'a str)]) -> Self {
        let tokens = lines
            .iter()
            .flat_map(|&(line, text)| {
                text.split(|c: char| c.is_whitespace() || c == ',')
                    .filter(|t| !t.is_empty())
                    .map(move |text| Token { text, line })
            })
            .collect();
        Tokens {
            path,
            tokens,
            next: 0,
            last_line: lines.last().map_or(1, |l| l.0),
        }
    }

    fn number(&mut self, what: &str) -> Result<(f64, usize)> {
        let Some(t) = self.tokens.get(self.next) else {
            return Err(Error::line(
                self.path,
                self.last_line,
                format!("the file ends where {what} should be"),
            ));
        };
        self.next += 1;
        let v: f64 = t.text.parse().map_err(|_| {
            Error::line(
                self.path,
                t.line,
                format!("{what}: '{}' is not a number", t.text),
            )
        })?;
        if !v.is_finite() {
            return Err(Error::line(
                self.path,
                t.line,
                format!("{what}: must be finite, found {}", t.text),
            ));
        }
        Ok((v, t.line))
    }

    fn count(&mut self, what: &str) -> Result<(u32, usize)> {
        let (v, line) = self.number(what)?;
        if v < 1.0 || v.fract() != 0.0 || v > 1e6 {
            return Err(Error::line(
                self.path,
                line,
                format!("{what}: must be a positive whole number, found {v}"),
            ));
        }
        Ok((v as u32, line))
    }

    /// `n` numbers, strictly increasing when they are angles.
    fn numbers(
        &mut self,
        n: usize,
        what: &str,
        increasing: bool,
    ) -> Result<(Vec<f64>, Vec<usize>)> {
        let mut values = Vec::with_capacity(n);
        let mut lines = Vec::with_capacity(n);
        for i in 0..n {
            let (v, line) = self.number(&format!("{what} {} of {n}", i + 1))?;
            if increasing && values.last().is_some_and(|&p| v <= p) {
                return Err(Error::line(
                    self.path,
                    line,
                    format!(
                        "{what} {} of {n} is {v} after {}: angles must increase (does the header's count of {n} match the angles listed? a count too high reads the next list's first value as one of these)",
                        i + 1,
                        values[i - 1]
                    ),
                ));
            }
            values.push(v);
            lines.push(line);
        }
        Ok((values, lines))
    }
}

impl IesProfile {
    /// Reads and parses an IES file; `TILT=<file>` is read relative to it.
    pub fn load(path: &Path) -> Result<IesProfile> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
        // Old files are often Latin-1: keep the label bytes as best we can.
        let text = String::from_utf8_lossy(&bytes);
        Self::parse(&text, path)
    }

    /// Parses the text of an IES file; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<IesProfile> {
        let lines: Vec<(usize, &str)> = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim_end_matches('\r')))
            .collect();
        if lines.iter().all(|(_, l)| l.trim().is_empty()) {
            return Err(Error::file(path, "empty IES file"));
        }
        let tilt_at = lines
            .iter()
            .position(|(_, l)| l.trim_start().to_ascii_uppercase().starts_with("TILT"))
            .ok_or_else(|| {
                Error::line(
                    path,
                    lines.len(),
                    "no TILT= line (every LM-63 file has one before the photometric data)",
                )
            })?;

        let (version, keywords) = header(&lines[..tilt_at]);
        let mut tokens = Tokens::new(path, &lines[tilt_at + 1..]);
        let tilt = tilt(path, lines[tilt_at], &mut tokens)?;
        let (lamps, _) = tokens.count("number of lamps")?;
        let (lumens_per_lamp, _) = tokens.number("lumens per lamp")?;
        let (multiplier, ml) = tokens.number("candela multiplier")?;
        if multiplier < 0.0 {
            return Err(Error::line(
                path,
                ml,
                "candela multiplier must not be negative",
            ));
        }
        let (nv, _) = tokens.count("number of vertical angles")?;
        let (nh, _) = tokens.count("number of horizontal angles")?;
        let (pt, ptl) = tokens.number("photometric type")?;
        let photometric_type = match pt as i64 {
            1 if pt == 1.0 => PhotometricType::C,
            2 if pt == 2.0 => PhotometricType::B,
            3 if pt == 3.0 => PhotometricType::A,
            _ => {
                return Err(Error::line(
                    path,
                    ptl,
                    format!("photometric type must be 1 (C), 2 (B) or 3 (A), found {pt}"),
                ));
            }
        };
        let (units, ul) = tokens.number("units type")?;
        if units != 1.0 && units != 2.0 {
            return Err(Error::line(
                path,
                ul,
                format!("units type must be 1 (feet) or 2 (metres), found {units}"),
            ));
        }
        let (width, _) = tokens.number("width")?;
        let (length, _) = tokens.number("length")?;
        let (height, _) = tokens.number("height")?;
        let (ballast_factor, _) = tokens.number("ballast factor")?;
        let (ballast_lamp_factor, _) = tokens.number("ballast-lamp photometric factor")?;
        let (input_watts, _) = tokens.number("input watts")?;
        let (vertical, vlines) = tokens.numbers(nv as usize, "vertical angle", true)?;
        let (horizontal, hlines) = tokens.numbers(nh as usize, "horizontal angle", true)?;
        let (candela, clines) = tokens.numbers((nv * nh) as usize, "candela value", false)?;
        if let Some(i) = candela.iter().position(|&c| c < 0.0) {
            return Err(Error::line(
                path,
                clines[i],
                format!("candela value {} is negative", candela[i]),
            ));
        }
        if let Some(t) = tokens.tokens.get(tokens.next) {
            return Err(Error::line(
                path,
                t.line,
                format!(
                    "unexpected '{}' after the {} candela values (arlux reads one luminaire per file)",
                    t.text,
                    nv * nh
                ),
            ));
        }

        let profile = IesProfile {
            version,
            keywords,
            tilt,
            lamps,
            lumens_per_lamp,
            multiplier,
            photometric_type,
            units: units as u32,
            width,
            length,
            height,
            ballast_factor,
            ballast_lamp_factor,
            input_watts,
            vertical,
            horizontal,
            candela,
        };
        profile.check_angles(
            path,
            vlines[0],
            *vlines.last().unwrap(),
            hlines[0],
            *hlines.last().unwrap(),
        )?;
        Ok(profile)
    }

    fn check_angles(
        &self,
        path: &Path,
        v_first_line: usize,
        v_last_line: usize,
        h_first_line: usize,
        h_last_line: usize,
    ) -> Result<()> {
        let (v0, v1) = (self.vertical[0], *self.vertical.last().unwrap());
        let (h0, h1) = (self.horizontal[0], *self.horizontal.last().unwrap());
        match self.photometric_type {
            PhotometricType::C => {
                if v0 != 0.0 && v0 != 90.0 {
                    return Err(Error::line(
                        path,
                        v_first_line,
                        format!("type C vertical angles start at 0 or 90, not {v0}"),
                    ));
                }
                if v1 > 180.0 {
                    return Err(Error::line(
                        path,
                        v_last_line,
                        format!("type C vertical angles end at 180 at most, not {v1}"),
                    ));
                }
                let symmetric =
                    (h0 == 0.0 && [0.0, 90.0, 180.0].contains(&h1)) || (h0 == 90.0 && h1 == 270.0);
                let full = h0 == 0.0 && h1 > 180.0 && h1 <= 360.0;
                if !(symmetric || full) {
                    let line = if h0 != 0.0 && h0 != 90.0 {
                        h_first_line
                    } else {
                        h_last_line
                    };
                    return Err(Error::line(
                        path,
                        line,
                        format!(
                            "type C horizontal angles {h0}..{h1} are none of 0, 0-90, 0-180, 90-270, 0-360"
                        ),
                    ));
                }
            }
            PhotometricType::B | PhotometricType::A => {
                if !((v0 == -90.0 || v0 == 0.0) && v1 <= 90.0) {
                    return Err(Error::line(
                        path,
                        v_first_line,
                        format!(
                            "type A/B vertical angles lie in -90..90 starting at -90 or 0, not {v0}..{v1}"
                        ),
                    ));
                }
                if !((h0 == -90.0 || h0 == 0.0) && h1 <= 90.0) {
                    return Err(Error::line(
                        path,
                        h_first_line,
                        format!(
                            "type A/B horizontal angles lie in -90..90 starting at -90 or 0, not {h0}..{h1}"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The product of the file's multipliers: candela multiplier × ballast
    /// factor × ballast-lamp photometric factor.
    pub fn scale(&self) -> f64 {
        self.multiplier * self.ballast_factor * self.ballast_lamp_factor
    }

    /// Candela at the file's own angles (degrees), folded by the file's
    /// symmetry and interpolated bilinearly; 0 outside the measured range.
    pub fn candela(&self, vertical_deg: f64, horizontal_deg: f64) -> f64 {
        let (v, h) = self.fold(vertical_deg, horizontal_deg);
        let nv = self.vertical.len();
        let Some((vi, vt)) = bracket(&self.vertical, v) else {
            return 0.0;
        };
        let (hi, ht, hj) = match self.horizontal.len() {
            1 => (0, 0.0, 0),
            _ => match bracket(&self.horizontal, h) {
                Some((hi, ht)) => (hi, ht, (hi + 1).min(self.horizontal.len() - 1)),
                None => {
                    // A full type C circle that stops short of 360: wrap to 0.
                    let last = *self.horizontal.last().unwrap();
                    if self.photometric_type == PhotometricType::C && h > last {
                        (self.horizontal.len() - 1, (h - last) / (360.0 - last), 0)
                    } else {
                        return 0.0;
                    }
                }
            },
        };
        let vj = (vi + 1).min(nv - 1);
        let at = |hk: usize, vk: usize| self.candela[hk * nv + vk];
        let lower = at(hi, vi) * (1.0 - vt) + at(hi, vj) * vt;
        let upper = at(hj, vi) * (1.0 - vt) + at(hj, vj) * vt;
        (lower * (1.0 - ht) + upper * ht) * self.scale()
    }

    /// Maps angles into the range the file covers, by its symmetry.
    fn fold(&self, v: f64, h: f64) -> (f64, f64) {
        let (h0, h1) = (self.horizontal[0], *self.horizontal.last().unwrap());
        match self.photometric_type {
            PhotometricType::C => {
                let mut h = h.rem_euclid(360.0);
                if h1 == 0.0 {
                    h = 0.0;
                } else if h0 == 90.0 && h1 == 270.0 {
                    if h < 90.0 {
                        h = 180.0 - h;
                    } else if h > 270.0 {
                        h = 540.0 - h;
                    }
                } else if h1 <= 180.0 {
                    if h > 180.0 {
                        h = 360.0 - h;
                    }
                    if h1 <= 90.0 && h > 90.0 {
                        h = 180.0 - h;
                    }
                }
                (v, h)
            }
            PhotometricType::B | PhotometricType::A => {
                let v = if self.vertical[0] == 0.0 { v.abs() } else { v };
                let h = if h0 == 0.0 { h.abs() } else { h };
                (v, h)
            }
        }
    }

    /// Candela towards a unit direction in the luminaire frame: `axis` is
    /// photometric zero (type C nadir; the aim of types A and B), `reference`
    /// the photometric horizontal at horizontal angle 0, and `side` =
    /// axis × reference the direction at horizontal angle 90.
    pub fn candela_towards(&self, d: DVec3, axis: DVec3, reference: DVec3) -> f64 {
        let side = axis.cross(reference);
        let (a, r, s) = (d.dot(axis), d.dot(reference), d.dot(side));
        let (v, h) = match self.photometric_type {
            // d = cosV·axis + sinV·(cosH·reference + sinH·side)
            PhotometricType::C => (
                a.clamp(-1.0, 1.0).acos().to_degrees(),
                s.atan2(r).to_degrees(),
            ),
            // d = cosV·(cosH·axis + sinH·side) + sinV·reference
            PhotometricType::B => (
                r.clamp(-1.0, 1.0).asin().to_degrees(),
                s.atan2(a).to_degrees(),
            ),
            // d = cosV·(cosH·reference + sinH·side) − sinV·axis
            PhotometricType::A => (
                (-a).clamp(-1.0, 1.0).asin().to_degrees(),
                s.atan2(r).to_degrees(),
            ),
        };
        self.candela(v, h)
    }

    /// The file's text in LM-63-2002 form (TILT=INCLUDE when it has a tilt).
    pub fn to_lm63(&self) -> String {
        let mut out = String::new();
        let version = if self.version.is_empty() {
            "IESNA:LM-63-2002"
        } else {
            &self.version
        };
        let _ = writeln!(out, "{version}");
        for (k, v) in &self.keywords {
            if k.is_empty() {
                let _ = writeln!(out, "{v}");
            } else {
                let _ = writeln!(out, "[{k}] {v}");
            }
        }
        let row = |out: &mut String, values: &[f64]| {
            // At most ~10 numbers a line keeps lines short, as the standard asks.
            for chunk in values.chunks(10) {
                let line: Vec<String> = chunk.iter().map(|v| format!("{v}")).collect();
                let _ = writeln!(out, "{}", line.join(" "));
            }
        };
        match &self.tilt {
            None => {
                let _ = writeln!(out, "TILT=NONE");
            }
            Some(t) => {
                let _ = writeln!(out, "TILT=INCLUDE");
                let _ = writeln!(out, "{}", t.lamp_geometry);
                let _ = writeln!(out, "{}", t.angles.len());
                row(&mut out, &t.angles);
                row(&mut out, &t.factors);
            }
        }
        let _ = writeln!(
            out,
            "{} {} {} {} {} {} {} {} {} {}",
            self.lamps,
            self.lumens_per_lamp,
            self.multiplier,
            self.vertical.len(),
            self.horizontal.len(),
            self.photometric_type as u32,
            self.units,
            self.width,
            self.length,
            self.height
        );
        let _ = writeln!(
            out,
            "{} {} {}",
            self.ballast_factor, self.ballast_lamp_factor, self.input_watts
        );
        row(&mut out, &self.vertical);
        row(&mut out, &self.horizontal);
        for h in self.candela.chunks(self.vertical.len()) {
            row(&mut out, h);
        }
        out
    }
}

/// The lines before TILT: the version line and the keywords.
fn header(lines: &[(usize, &str)]) -> (String, Vec<(String, String)>) {
    let mut version = String::new();
    let mut keywords = Vec::new();
    for (k, &(_, line)) in lines.iter().enumerate() {
        let l = line.trim();
        let upper = l.to_ascii_uppercase();
        if k == 0 && (upper.starts_with("IESNA") || upper.starts_with("IES:")) {
            version = l.to_string();
        } else if let Some(rest) = l.strip_prefix('[') {
            let (key, value) = rest.split_once(']').unwrap_or((rest, ""));
            keywords.push((key.trim().to_string(), value.trim().to_string()));
        } else if !l.is_empty() {
            keywords.push((String::new(), l.to_string()));
        }
    }
    (version, keywords)
}

/// The TILT line's tilt: none, included (read from `tokens`) or from the
/// file it names, beside `path`.
fn tilt(path: &Path, (line_no, line): (usize, &str), tokens: &mut Tokens) -> Result<Option<Tilt>> {
    let value = line
        .trim()
        .split_once('=')
        .map(|(_, v)| v.trim())
        .ok_or_else(|| {
            Error::line(
                path,
                line_no,
                "TILT line needs '=': TILT=NONE, TILT=INCLUDE or TILT=<file>",
            )
        })?;
    match value.to_ascii_uppercase().as_str() {
        "NONE" => Ok(None),
        "INCLUDE" => Ok(Some(read_tilt(tokens)?)),
        "" => Err(Error::line(
            path,
            line_no,
            "TILT= is empty: give NONE, INCLUDE or a file",
        )),
        _ => {
            let tilt_path = path.parent().unwrap_or(Path::new("")).join(value);
            let tilt_text = std::fs::read_to_string(&tilt_path).map_err(|e| {
                Error::io(&tilt_path, &e).within(path, format!("line {line_no}: TILT"))
            })?;
            let tilt_lines: Vec<(usize, &str)> = tilt_text
                .lines()
                .enumerate()
                .map(|(i, l)| (i + 1, l))
                .collect();
            let mut t = Tokens::new(&tilt_path, &tilt_lines);
            Ok(Some(read_tilt(&mut t)?))
        }
    }
}

fn read_tilt(tokens: &mut Tokens) -> Result<Tilt> {
    let (g, gl) = tokens.count("lamp-to-luminaire geometry")?;
    if g > 3 {
        return Err(Error::line(
            tokens.path,
            gl,
            format!("lamp-to-luminaire geometry must be 1, 2 or 3, found {g}"),
        ));
    }
    let (n, _) = tokens.count("number of tilt angles")?;
    let (angles, _) = tokens.numbers(n as usize, "tilt angle", true)?;
    let (factors, _) = tokens.numbers(n as usize, "tilt multiplying factor", false)?;
    Ok(Tilt {
        lamp_geometry: g,
        angles,
        factors,
    })
}

/// The interval of sorted `xs` holding `x`: (index, fraction), or None outside.
fn bracket(xs: &[f64], x: f64) -> Option<(usize, f64)> {
    const EPS: f64 = 1e-9;
    let (first, last) = (xs[0], *xs.last().unwrap());
    if x < first - EPS || x > last + EPS {
        return None;
    }
    if xs.len() == 1 {
        return Some((0, 0.0));
    }
    let x = x.clamp(first, last);
    let i = xs
        .partition_point(|&a| a <= x)
        .saturating_sub(1)
        .min(xs.len() - 2);
    Some((i, (x - xs[i]) / (xs[i + 1] - xs[i])))
}

fn interpolate_1d(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    match bracket(xs, x) {
        Some((i, t)) if xs.len() > 1 => ys[i] * (1.0 - t) + ys[i + 1] * t,
        Some(_) => ys[0],
        None if x < xs[0] => ys[0],
        None => *ys.last().unwrap(),
    }
}

#[cfg(test)]
mod tests;
