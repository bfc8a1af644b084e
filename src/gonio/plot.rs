use plotters::prelude::*;

use super::*;

/// Where a figure could not be drawn.
fn drawing(e: impl std::fmt::Display) -> String {
    format!("could not draw the plot: {e}")
}

/// A picture of the recovered distribution (cf. Grosch Fig. 7), as RGB8:
/// left, the polar candela diagram in the vertical plane through the peak
/// and the plane at right angles to it, nadir down, grey where no pixel
/// saw the light, rings labelled in candela (the IES table's units), scaled
/// to the 99th percentile of the known values; right, the whole table as
/// a map (horizontal angle across, vertical angle down from nadir) with
/// its candela colour bar, unknown directions grey.
pub fn polar_plot(rec: &Reconstruction) -> std::result::Result<(u32, u32, Vec<u8>), String> {
    crate::util::figure::register_font();
    let (w, h) = (1100u32, 540u32);
    let mut px = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut px, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(drawing)?;
        let directions = rec.profile.candela.len();
        let title = format!(
            "recovered goniometric: {} directions, {:.0}% of the sphere seen",
            directions,
            100.0 * rec.coverage
        );
        let root = root.titled(&title, ("sans-serif", 20)).map_err(drawing)?;
        let (left, right) = root.split_horizontally(520);
        let scale = scale_value(rec);
        polar_panel(rec, &left, scale)?;
        map_panel(rec, &right, scale)?;
        root.present().map_err(drawing)?;
    }
    Ok((w, h, px))
}

/// The 99th percentile of the known values: a few nodes at surfaces' rims
/// can spike, and would squash the whole diagram.
fn scale_value(rec: &Reconstruction) -> f64 {
    let mut known: Vec<f64> = rec
        .profile
        .candela
        .iter()
        .zip(&rec.known)
        .filter(|(_, k)| **k)
        .map(|(c, _)| *c)
        .collect();
    known.sort_by(f64::total_cmp);
    known
        .get(known.len() * 99 / 100)
        .copied()
        .unwrap_or(0.0)
        .max(1e-300)
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn polar_panel(rec: &Reconstruction, area: &Area, scale: f64) -> std::result::Result<(), String> {
    let r = 1.1 * scale;
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(-r..r, -r..r)
        .map_err(drawing)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("candela (in the plane)")
        .y_desc("candela (nadir down)")
        .label_style(("sans-serif", 13))
        .x_label_formatter(&|v| format!("{:.0}", v.abs()))
        .y_label_formatter(&|v| format!("{:.0}", v.abs()))
        .draw()
        .map_err(drawing)?;
    let grey = RGBColor(215, 215, 215);
    for ring in 1..=4 {
        let rr = scale * ring as f64 / 4.0;
        let circle = (0..=120).map(|i| {
            let a = i as f64 / 120.0 * std::f64::consts::TAU;
            (rr * a.cos(), rr * a.sin())
        });
        chart
            .draw_series(LineSeries::new(circle, grey))
            .map_err(drawing)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("{:.0} cd", rr),
                (rr * 0.71, rr * 0.71),
                ("sans-serif", 12)
                    .into_font()
                    .color(&RGBColor(110, 110, 110)),
            )))
            .map_err(drawing)?;
    }
    for spoke in 0..12 {
        let a = spoke as f64 * 30f64.to_radians();
        chart
            .draw_series(LineSeries::new(
                [(0.0, 0.0), (scale * a.cos(), scale * a.sin())],
                grey,
            ))
            .map_err(drawing)?;
    }
    let (_, peak_dir) = peak(rec);
    let (_, peak_h) = angles(peak_dir);
    let planes = [
        (peak_h, RGBColor(230, 120, 20), "through the peak"),
        (peak_h + 90.0, RGBColor(40, 90, 200), "at right angles"),
    ];
    for (h0, colour, what) in planes {
        // γ ∈ [0, 360) from nadir; past 180° the opposite horizontal angle.
        let point = |gamma: f64| {
            let (v, hh) = if gamma <= 180.0 {
                (gamma, h0)
            } else {
                (360.0 - gamma, h0 + 180.0)
            };
            let d = direction_at(v, hh);
            let value = rec
                .profile
                .candela_towards(d, AXIS, REFERENCE)
                .min(1.05 * scale);
            let a = gamma.to_radians();
            ((value * a.sin(), -value * a.cos()), rec.is_known(d))
        };
        let points: Vec<((f64, f64), bool)> = (0..=720).map(|i| point(i as f64 * 0.5)).collect();
        let label = format!("plane H = {:.0}° ({what})", h0.rem_euclid(360.0));
        chart
            .draw_series(
                points
                    .windows(2)
                    .filter(|p| p[0].1 && p[1].1)
                    .map(|p| PathElement::new(vec![p[0].0, p[1].0], colour.stroke_width(2))),
            )
            .map_err(drawing)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(
                points
                    .windows(2)
                    .filter(|p| !(p[0].1 && p[1].1))
                    .map(|p| PathElement::new(vec![p[0].0, p[1].0], RGBColor(170, 170, 170))),
            )
            .map_err(drawing)?;
    }
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
        .map_err(drawing)?
        .label("unseen directions (grey)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RGBColor(170, 170, 170)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(("sans-serif", 12))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(drawing)
}

fn map_panel(rec: &Reconstruction, area: &Area, scale: f64) -> std::result::Result<(), String> {
    let (map, bar) = area.split_horizontally(480);
    let mut chart = ChartBuilder::on(&map)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..360.0, 180.0..0.0)
        .map_err(drawing)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("horizontal angle (°)")
        .y_desc("vertical angle from nadir (°)")
        .label_style(("sans-serif", 13))
        .x_labels(9)
        .y_labels(7)
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(drawing)?;
    let (nh, nv) = (180, 90);
    let cells = (0..nv)
        .flat_map(|i| (0..nh).map(move |j| (i, j)))
        .map(|(i, j)| {
            let (v0, h0) = (i as f64 * 180.0 / nv as f64, j as f64 * 360.0 / nh as f64);
            let d = direction_at(v0 + 1.0, h0 + 1.0);
            let colour = if rec.is_known(d) {
                heat(rec.profile.candela_towards(d, AXIS, REFERENCE) / scale)
            } else {
                RGBColor(225, 225, 225)
            };
            Rectangle::new([(h0, v0), (h0 + 2.0, v0 + 2.0)], colour.filled())
        });
    chart.draw_series(cells).map_err(drawing)?;
    let mut bar = ChartBuilder::on(&bar)
        .margin_top(10)
        .margin_bottom(45)
        .y_label_area_size(45)
        .build_cartesian_2d(0.0..1.0, 0.0..scale)
        .map_err(drawing)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("candela")
        .label_style(("sans-serif", 12))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(drawing)?;
    bar.draw_series((0..100).map(|i| {
        let (a, b) = (i as f64 / 100.0 * scale, (i + 1) as f64 / 100.0 * scale);
        Rectangle::new([(0.0, a), (1.0, b)], heat(a / scale).filled())
    }))
    .map_err(drawing)?;
    Ok(())
}

/// Black → red → yellow → white.
fn heat(t: f64) -> RGBColor {
    let c = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    let t = t.clamp(0.0, 1.0);
    RGBColor(c(3.0 * t), c(3.0 * t - 1.0), c(3.0 * t - 2.0))
}
