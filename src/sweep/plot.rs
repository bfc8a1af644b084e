//! A sweep's figure: error where the change is against run time, both on
//! log scales, each method's points, arlux's Pareto front, the peers'
//! curves and the reference's noise as a floor.

use std::path::Path;

use super::{SweepMethod, SweepRow, SweepSettings};
use crate::error::{Error, Result};

/// Error against time, every row a point, the front joined and ringed;
/// text drawn with the font shipped in `assets/` (no system font needed).
pub fn plot(rows: &[SweepRow], title: &str, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    crate::util::figure::register_font();
    let (w, h) = (900u32, 600u32);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    let fail = |e: String| Error::file(path, format!("could not draw the plot: {e}"));
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        // Times span orders of magnitude (a fine room mesh costs 40× a
        // coarse one): x is log10(seconds), labelled in seconds (plotters'
        // own log axis draws no tick inside a narrow range).
        let lt = |t: f64| t.max(1e-4).log10();
        let ly = |e: f64| e.max(1e-6).log10();
        let t_min = rows.iter().map(|r| r.seconds).fold(f64::INFINITY, f64::min) * 0.8;
        let t_max = rows.iter().map(|r| r.seconds_max).fold(0.0, f64::max) * 1.25;
        // The error where the change is, 1 − skill, also on a log scale:
        // the curve of more samples keeps falling by factors.
        let skilled = rows.iter().all(|r| r.skill.is_some());
        let floor = rows.iter().find_map(|r| r.skill_floor.filter(|_| skilled));
        let lowest = (rows.iter().map(|r| r.error()))
            .fold(floor.map_or(f64::INFINITY, |f| 1.0 - f), f64::min);
        // Room below the lowest point for the legend.
        let e_min = ly(lowest) - 0.3;
        let e_max = ly(rows.iter().map(|r| r.error()).fold(0.0, f64::max)) + 0.05;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(
                lt(t_min)..lt(t_max).max(lt(t_min) + 0.05),
                e_min..e_max.max(e_min + 0.05),
            )
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("seconds (log scale)")
            .x_label_formatter(&|x| {
                let t = 10f64.powf(*x);
                if t < 1.0 {
                    format!("{t:.3}")
                } else {
                    format!("{t:.1}")
                }
            })
            .y_desc(if skilled {
                "1 − skill where the change is (log scale)"
            } else {
                "RMSE against the reference (log scale)"
            })
            .label_style(("sans-serif", 14))
            .y_label_formatter(&|y| format!("{:.4}", 10f64.powf(*y)))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        draw_rows(&mut chart, rows, e_max - e_min).map_err(fail)?;
        let x_range = (lt(t_min), lt(t_max).max(lt(t_min) + 0.05));
        match floor {
            Some(f) => {
                let y = ly(1.0 - f);
                chart
                    .draw_series(DashedLineSeries::new(
                        [(x_range.0, y), (x_range.1, y)],
                        8,
                        5,
                        RGBColor(150, 30, 150).stroke_width(2),
                    ))
                    .map_err(|e| fail(e.to_string()))?
                    .label(format!("the reference's noise (skill {f:.4})"))
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(150, 30, 150))
                    });
            }
            None => {
                root.draw(&Text::new(
                    "no reference noise declared (reference_noise): no floor drawn",
                    (110, (h - 20) as i32),
                    ("sans-serif", 13),
                ))
                .map_err(|e| fail(e.to_string()))?;
            }
        }
        chart
            .configure_series_labels()
            // Below the curves, which fall from the upper left.
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    crate::image_io::write_png_rgb8(path, w, h, buffer)
}

/// The sweep's chart: x is log10(seconds), y log10 of the error.
type Chart<'a, 'b> = plotters::chart::ChartContext<
    'a,
    plotters::backend::BitMapBackend<'b>,
    plotters::coord::cartesian::Cartesian2d<
        plotters::coord::types::RangedCoordf64,
        plotters::coord::types::RangedCoordf64,
    >,
>;

/// The rows on `chart`: each method's points, the Pareto front and the
/// defaults, with their legend entries; `span` is the error axis's range
/// (in log10).
fn draw_rows(chart: &mut Chart, rows: &[SweepRow], span: f64) -> std::result::Result<(), String> {
    use plotters::prelude::*;
    if rows.iter().all(|r| r.peer.is_some()) {
        // `--peer-only`: no point, front or defaults of arlux's.
        return draw_peers(chart, rows);
    }
    let lt = |t: f64| t.max(1e-4).log10();
    let ly = |e: f64| e.max(1e-6).log10();
    let err = |e: DrawingAreaErrorKind<_>| e.to_string();
    // Each point sits at its fastest run; a bar reaches its slowest, with
    // a tick at the median (`--repeats`).
    let spread = |r: &&SweepRow| r.peer.is_none() && r.seconds_max > r.seconds;
    chart
        .draw_series(rows.iter().filter(spread).map(|r| {
            let y = ly(r.error());
            PathElement::new(
                vec![(lt(r.seconds), y), (lt(r.seconds_max), y)],
                RGBColor(170, 170, 170),
            )
        }))
        .map_err(err)?;
    chart
        .draw_series(rows.iter().filter(spread).map(|r| {
            let (x, y) = (lt(r.seconds_median), ly(r.error()));
            PathElement::new(
                vec![(x, y - span * 0.008), (x, y + span * 0.008)],
                RGBColor(120, 120, 120),
            )
        }))
        .map_err(err)?;
    chart
        .draw_series(
            rows.iter()
                .filter(|r| r.settings.method == SweepMethod::Pda)
                .map(|r| {
                    Circle::new(
                        (lt(r.seconds), ly(r.error())),
                        3,
                        RGBColor(120, 120, 120).filled(),
                    )
                }),
        )
        .map_err(err)?
        .label("pixel path (pda)")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, RGBColor(120, 120, 120).filled()));
    let texture = |r: &&SweepRow| matches!(r.settings.method, SweepMethod::Texture { .. });
    if rows.iter().any(|r| texture(&r)) {
        chart
            .draw_series(rows.iter().filter(texture).map(|r| {
                Rectangle::new(
                    [
                        (lt(r.seconds) - 0.006, ly(r.error()) - span * 0.006),
                        (lt(r.seconds) + 0.006, ly(r.error()) + span * 0.006),
                    ],
                    RGBColor(40, 140, 60).filled(),
                )
            }))
            .map_err(err)?
            .label("texture path")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x + 6, y - 3), (x + 12, y + 3)],
                    RGBColor(40, 140, 60).filled(),
                )
            });
    }
    draw_peers(chart, rows)?;
    let mut front: Vec<&SweepRow> = rows.iter().filter(|r| r.pareto).collect();
    front.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    chart
        .draw_series(LineSeries::new(
            front.iter().map(|r| (lt(r.seconds), ly(r.error()))),
            RGBColor(220, 90, 20).stroke_width(2),
        ))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| {
            PathElement::new(
                vec![(x, y), (x + 20, y)],
                RGBColor(220, 90, 20).stroke_width(2),
            )
        });
    chart
        .draw_series(front.iter().map(|r| {
            Circle::new(
                (lt(r.seconds), ly(r.error())),
                6,
                RGBColor(220, 90, 20).stroke_width(2),
            )
        }))
        .map_err(err)?;
    let d = SweepSettings::defaults();
    chart
        .draw_series(
            rows.iter()
                .filter(|r| r.settings == d)
                .map(|r| TriangleMarker::new((lt(r.seconds), ly(r.error())), 9, BLUE.filled())),
        )
        .map_err(err)?
        .label("defaults")
        .legend(|(x, y)| TriangleMarker::new((x + 10, y), 6, BLUE.filled()));
    Ok(())
}

/// Each peer's rows as a curve of its own, in time order, with its label.
fn draw_peers(chart: &mut Chart, rows: &[SweepRow]) -> std::result::Result<(), String> {
    use plotters::prelude::*;
    let lt = |t: f64| t.max(1e-4).log10();
    let ly = |e: f64| e.max(1e-6).log10();
    let err = |e: DrawingAreaErrorKind<_>| e.to_string();
    let mut labels: Vec<&str> = Vec::new();
    for r in rows {
        if let Some(l) = r.peer.as_deref().filter(|l| !labels.contains(l)) {
            labels.push(l);
        }
    }
    const COLOURS: [RGBColor; 4] = [
        RGBColor(200, 30, 40),
        RGBColor(30, 110, 200),
        RGBColor(120, 80, 20),
        RGBColor(20, 150, 150),
    ];
    for (k, label) in labels.into_iter().enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        let mut points: Vec<(f64, f64)> = (rows.iter())
            .filter(|r| r.peer.as_deref() == Some(label))
            .map(|r| (lt(r.seconds), ly(r.error())))
            .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(err)?
            .label(label.to_string())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&p| Cross::new(p, 5, colour.stroke_width(2))),
            )
            .map_err(err)?;
    }
    Ok(())
}
