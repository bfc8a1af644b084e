use super::*;

/// A picture of the recovered distribution (cf. Grosch Fig. 7), as RGB8:
/// left, the polar candela diagram in the vertical plane through the peak
/// (orange) and the plane at right angles to it (blue), nadir down, grey
/// where unknown, scaled to the 99th percentile of the known values (the
/// outer ring); right, the whole table as a map (horizontal angle across,
/// vertical angle down from nadir), unknown directions hatched.
pub fn polar_plot(rec: &Reconstruction) -> (u32, u32, Vec<u8>) {
    const S: i64 = 480;
    let (w, h) = (2 * S as u32, S as u32);
    let mut canvas = Canvas {
        px: vec![255u8; (w * h * 3) as usize],
        w,
        h,
    };
    let p = &rec.profile;
    let (_, peak_dir) = peak(rec);
    // Scale to the 99th percentile of the known values: a few nodes at
    // surfaces' rims can spike, and would squash the whole diagram.
    let mut known_values: Vec<f64> = p
        .candela
        .iter()
        .zip(&rec.known)
        .filter(|(_, k)| **k)
        .map(|(c, _)| *c)
        .collect();
    known_values.sort_by(f64::total_cmp);
    let peak_value = known_values
        .get(known_values.len() * 99 / 100)
        .copied()
        .unwrap_or(0.0)
        .max(1e-300);
    let (_, peak_h) = angles(peak_dir);
    // Polar diagram: centre, radius for the peak.
    let (cx, cy, r) = (S as f64 / 2.0, S as f64 / 2.0, S as f64 * 0.45);
    let grid_c = [220, 220, 220];
    for ring in 1..=4 {
        let rr = r * ring as f64 / 4.0;
        let steps = 360;
        for i in 0..steps {
            let (a0, a1) = (
                i as f64 / steps as f64 * std::f64::consts::TAU,
                (i + 1) as f64 / steps as f64 * std::f64::consts::TAU,
            );
            canvas.line(
                (cx + rr * a0.cos(), cy + rr * a0.sin()),
                (cx + rr * a1.cos(), cy + rr * a1.sin()),
                grid_c,
            );
        }
    }
    for spoke in 0..12 {
        let a = spoke as f64 * 30f64.to_radians();
        canvas.line((cx, cy), (cx + r * a.cos(), cy + r * a.sin()), grid_c);
    }
    // A plane through the axis: angle γ ∈ [0, 360) from nadir, the second
    // half being the opposite horizontal angle.
    for (h0, colour) in [
        (peak_h, [230u8, 120u8, 20u8]),
        (peak_h + 90.0, [40u8, 90u8, 200u8]),
    ] {
        let point = |gamma: f64| -> ((f64, f64), bool) {
            let (v, hh) = if gamma <= 180.0 {
                (gamma, h0)
            } else {
                (360.0 - gamma, h0 + 180.0)
            };
            let d = direction_at(v, hh);
            let value = (p.candela_towards(d, AXIS, REFERENCE) / peak_value).min(1.05);
            let known = rec.is_known(d);
            // Nadir down on the picture; the plane's h0 side to the right.
            let a = gamma.to_radians();
            ((cx + r * value * a.sin(), cy + r * value * a.cos()), known)
        };
        let mut prev = point(0.0);
        for i in 1..=720 {
            let next = point(i as f64 * 0.5);
            let c = if prev.1 && next.1 {
                colour
            } else {
                [170, 170, 170]
            };
            canvas.line(prev.0, next.0, c);
            canvas.line((prev.0.0 + 1.0, prev.0.1), (next.0.0 + 1.0, next.0.1), c);
            prev = next;
        }
    }
    // The map: x = horizontal angle, y = vertical angle.
    let (x0, y0, mw, mh) = (S as f64 + 20.0, 60.0, S as f64 - 40.0, S as f64 - 120.0);
    for yy in 0..mh as i64 {
        for xx in 0..mw as i64 {
            let v = (yy as f64 + 0.5) / mh * 180.0;
            let hh = (xx as f64 + 0.5) / mw * 360.0;
            let d = direction_at(v, hh);
            let c = if rec.is_known(d) {
                heat((p.candela_towards(d, AXIS, REFERENCE) / peak_value).clamp(0.0, 1.0))
            } else if (xx + yy) % 8 < 2 {
                [150, 150, 150]
            } else {
                [235, 235, 235]
            };
            canvas.put(x0 as i64 + xx, y0 as i64 + yy, c);
        }
    }
    let nv_lines = [0.0, 45.0, 90.0, 135.0, 180.0];
    for v in nv_lines {
        let y = y0 + v / 180.0 * mh;
        canvas.line((x0, y), (x0 + mw, y), [255, 255, 255]);
    }
    for hh in [90.0, 180.0, 270.0] {
        let x = x0 + hh / 360.0 * mw;
        canvas.line((x, y0), (x, y0 + mh), [255, 255, 255]);
    }
    (w, h, canvas.px)
}

/// An RGB8 picture to draw on.
struct Canvas {
    px: Vec<u8>,
    w: u32,
    h: u32,
}

impl Canvas {
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && x < self.w as i64 && y < self.h as i64 {
            let i = ((y as u32 * self.w + x as u32) * 3) as usize;
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }

    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: [u8; 3]) {
        let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as i64).max(1);
        for i in 0..=n {
            let t = i as f64 / n as f64;
            self.put(
                (a.0 + (b.0 - a.0) * t).round() as i64,
                (a.1 + (b.1 - a.1) * t).round() as i64,
                c,
            );
        }
    }
}

/// Black → red → yellow → white.
fn heat(t: f64) -> [u8; 3] {
    let c = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    [c(3.0 * t), c(3.0 * t - 1.0), c(3.0 * t - 2.0)]
}
