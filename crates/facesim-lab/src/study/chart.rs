//! The study's charts, each written as SVG and PNG (plotters; text in the PNGs with the bundled
//! DejaVu Sans, so no system font library is needed).

use super::benchmarks::Benchmark;
use super::face::FaceRow;
use crate::dynamics::Integrator;
use facesim::error::{Error, Result};
use facesim::output::write_atomic;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

use facesim_charts::sweep::{DrawResult, FONT, PALETTE};

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Draw with `draw` into `<stem>.svg` and `<stem>.png` (atomically).
fn both(
    dir: &Path,
    stem: &str,
    size: (u32, u32),
    draw: &dyn Fn(DrawingArea<SVGBackend, Shift>) -> DrawResult,
    draw_png: &dyn Fn(DrawingArea<BitMapBackend, Shift>) -> DrawResult,
) -> Result<()> {
    register_font();
    let svg = dir.join(format!("{stem}.svg"));
    write_atomic(&svg, |tmp| {
        let root = SVGBackend::new(tmp, size).into_drawing_area();
        draw(root).map_err(|e| Error::output(&svg, e.to_string()))
    })?;
    let png = dir.join(format!("{stem}.png"));
    write_atomic(&png, |tmp| {
        let root = BitMapBackend::new(tmp, size).into_drawing_area();
        draw_png(root).map_err(|e| Error::output(&png, e.to_string()))
    })
}

fn integrator_name(i: Integrator) -> &'static str {
    match i {
        Integrator::ImplicitNewmark => "implicit Newmark",
        Integrator::ExplicitConsistent => "explicit, consistent mass",
        Integrator::ExplicitLumped => "explicit, lumped mass",
        Integrator::QuasiStatic => "quasi-static",
    }
}

/// Error over time for one benchmark: three panels (energy, surface, interior), one line per
/// integrator against the implicit reference; a diverged run ends in a cross and says where.
pub fn error_over_time(dir: &Path, stem: &str, b: &Benchmark) -> Result<()> {
    fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, b: &Benchmark) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let (title, body) = root.split_vertically(40);
        title.titled(
            &format!(
                "{} ({}, h = 1/30 s): error against implicit Newmark",
                b.name, b.mesh
            ),
            ("sans-serif", 20),
        )?;
        let panels = body.split_evenly((1, 3));
        let t_end = b.steps as f64 * b.h;
        for (k, (panel, metric)) in panels
            .iter()
            .zip(["relative energy norm", "surface error", "interior error"])
            .enumerate()
        {
            let get = |s: &super::benchmarks::Series| -> Vec<f64> {
                match k {
                    0 => s.energy.clone(),
                    1 => s.surface.clone(),
                    _ => s.interior.clone(),
                }
            };
            let mut lo = f64::INFINITY;
            let mut hi = 0.0f64;
            for s in b.series.iter().skip(1) {
                for v in get(s).into_iter().filter(|v| *v > 0.0 && v.is_finite()) {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            if !(hi > 0.0) {
                lo = 1e-6;
                hi = 1.0;
            }
            let lo = lo.max(hi * 1e-8);
            let mut chart = ChartBuilder::on(panel)
                .caption(metric, ("sans-serif", 16))
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_end, (lo * 0.8..hi * 1.25).log_scale())?;
            chart
                .configure_mesh()
                .x_desc("t (s)")
                .y_label_formatter(&|v| format!("{v:.0e}"))
                .draw()?;
            for (i, s) in b.series.iter().enumerate().skip(1) {
                let color = PALETTE[i % PALETTE.len()];
                let vals = get(s);
                let pts: Vec<(f64, f64)> = s
                    .time
                    .iter()
                    .zip(&vals)
                    .map(|(t, v)| (*t, v.max(lo)))
                    .collect();
                let label = match &s.diverged {
                    Some(d) => format!("{} — {d}", integrator_name(s.integrator)),
                    None => integrator_name(s.integrator).to_string(),
                };
                chart
                    .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                    .label(label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                    });
                if s.diverged.is_some() {
                    let at = pts.last().copied().unwrap_or((0.0, hi));
                    chart.draw_series(std::iter::once(Cross::new(at, 8, color.stroke_width(3))))?;
                }
            }
            if k == 0 {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .label_font(("sans-serif", 12))
                    .position(SeriesLabelPosition::LowerRight)
                    .draw()?;
            }
        }
        root.present()?;
        Ok(())
    }
    both(dir, stem, (1500, 480), &|r| draw(r, b), &|r| draw(r, b))
}

/// Indices of the Pareto-optimal rows (no other row is both faster and closer), by time.
pub fn pareto(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut best = f64::INFINITY;
    let mut front = Vec::new();
    for i in idx {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// A log-axis tick label with two significant digits (0.001, 0.02, 0.5, 1, 20): a fixed two
/// decimals printed every tick below 0.01 as "0.00".
pub(crate) fn log_tick_label(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return format!("{v}");
    }
    let decimals = (1 - v.log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Ticks of a log axis over [lo, hi]: labelled 1-2-5 per decade (every digit within one decade,
/// powers of ten only beyond four), light lines at every digit. Plotters' own log ticks start at
/// the first power of ten in the range, which left no label below 1 mm on the accuracy axis.
pub(crate) fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let span = (hi / lo).log10();
    let labelled: &[f64] = if span < 1.0 {
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    } else if span <= 4.0 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    let (mut bold, mut light) = (Vec::new(), Vec::new());
    for e in lo.log10().floor() as i32..=hi.log10().ceil() as i32 {
        for m in 1..=9 {
            let v = f64::from(m) * 10f64.powi(e);
            if !(lo..=hi).contains(&v) {
                continue;
            }
            light.push(v);
            if labelled.contains(&f64::from(m)) {
                bold.push(v);
            }
        }
    }
    (bold, light)
}

/// One plotted point: run time (s), mean distance (mm) and its row.
type AccuracyPoint<'a> = (f64, f64, &'a FaceRow);

/// The non-reference rows with a distance, x = `x_of` (run time or unknowns), floored at 1e-4
/// for the log axes.
fn accuracy_points(rows: &[FaceRow], x_of: fn(&FaceRow) -> f64) -> Vec<AccuracyPoint<'_>> {
    rows.iter()
        .filter(|r| !r.is_reference && x_of(r) > 0.0)
        .filter_map(|r| {
            r.distance
                .as_ref()
                .map(|d| (x_of(r).max(1e-4), d.mean.max(1e-4), r))
        })
        .collect()
}

/// The methods in order of first appearance (one colour each).
fn method_families(pts: &[AccuracyPoint]) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    for p in pts {
        if !seen.contains(&p.2.method) {
            seen.push(p.2.method.clone());
        }
    }
    seen
}

/// Axis ranges (x0, x1, y0, y1) around the points with a margin of a factor 1.6.
fn accuracy_bounds(pts: &[AccuracyPoint]) -> (f64, f64, f64, f64) {
    if pts.is_empty() {
        return (0.01, 10.0, 0.01, 10.0);
    }
    let (xmin, xmax) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.0), b.max(p.0))
    });
    let (ymin, ymax) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    (xmin / 1.6, xmax * 1.6, ymin / 1.6, ymax * 1.6)
}

fn accuracy_caption(case: &str, against: &str, reference: Option<&FaceRow>) -> String {
    match reference {
        Some(r) => format!(
            "{case}: accuracy vs {against} (reference: {} at {}, {:.1} s)",
            r.method, r.resolution, r.wall_s
        ),
        None => format!("{case}: accuracy vs {against}"),
    }
}

fn draw_accuracy<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    caption: &str,
    x_desc: &str,
    pts: &[AccuracyPoint],
    families: &[String],
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (xmin, xmax, ymin, ymax) = accuracy_bounds(pts);
    let ((xbold, xlight), (ybold, ylight)) = (log_ticks(xmin, xmax), log_ticks(ymin, ymax));
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (xmin..xmax)
                .log_scale()
                .with_key_points(xbold)
                .with_light_points(xlight),
            (ymin..ymax)
                .log_scale()
                .with_key_points(ybold)
                .with_light_points(ylight),
        )?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("mean distance to reference (mm)")
        .x_label_formatter(&|v| log_tick_label(*v))
        .y_label_formatter(&|v| log_tick_label(*v))
        .draw()?;
    let xy: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.1)).collect();
    let front: Vec<(f64, f64)> = pareto(&xy).into_iter().map(|i| xy[i]).collect();
    chart
        .draw_series(LineSeries::new(
            front.clone(),
            BLACK.mix(0.6).stroke_width(2),
        ))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2)));
    for (fi, fam) in families.iter().enumerate() {
        let color = PALETTE[fi % PALETTE.len()];
        let mine: Vec<&AccuracyPoint> = pts.iter().filter(|p| &p.2.method == fam).collect();
        chart
            .draw_series(
                mine.iter()
                    .map(|p| Circle::new((p.0, p.1), 6, color.filled())),
            )?
            .label(fam.clone())
            .legend(move |(x, y)| Circle::new((x + 9, y), 5, color.filled()));
        for p in &mine {
            chart.draw_series(std::iter::once(Text::new(
                p.2.resolution.clone(),
                (p.0 * 1.06, p.1 * 1.04),
                ("sans-serif", 11),
            )))?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Accuracy (mean distance to the reference, log) against run time (log) for one face case,
/// a point per method and resolution, the Pareto front joined.
pub fn accuracy_vs_time(dir: &Path, stem: &str, case: &str, rows: &[FaceRow]) -> Result<()> {
    accuracy_vs(
        dir,
        stem,
        case,
        rows,
        ("run time", "run time (s, springs + model + solve)"),
        |r| r.wall_s,
    )
}

/// The same against the unknowns each method solves for (log).
pub fn accuracy_vs_unknowns(dir: &Path, stem: &str, case: &str, rows: &[FaceRow]) -> Result<()> {
    accuracy_vs(
        dir,
        stem,
        case,
        rows,
        ("unknowns", "unknowns (free degrees of freedom)"),
        |r| r.unknowns as f64,
    )
}

fn accuracy_vs(
    dir: &Path,
    stem: &str,
    case: &str,
    rows: &[FaceRow],
    (against, x_desc): (&str, &str),
    x_of: fn(&FaceRow) -> f64,
) -> Result<()> {
    let pts = accuracy_points(rows, x_of);
    let families = method_families(&pts);
    let caption = accuracy_caption(case, against, rows.iter().find(|r| r.is_reference));
    both(
        dir,
        stem,
        (1100, 750),
        &|r| draw_accuracy(r, &caption, x_desc, &pts, &families),
        &|r| draw_accuracy(r, &caption, x_desc, &pts, &families),
    )
}

/// Per facial region, the mean distance to the reference of selected rows (grouped bars), with
/// the clinical tools' range of mean errors (0.6–0.9 mm, shaded) and the 2 mm clinicians
/// accept (dashed).
pub fn regions(dir: &Path, stem: &str, case: &str, rows: &[&FaceRow]) -> Result<()> {
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, Shift>,
        case: &str,
        rows: &[&FaceRow],
    ) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let names: Vec<&str> = super::regions::NAMES
            .iter()
            .copied()
            .filter(|n| {
                rows.iter()
                    .any(|r| r.regions.iter().any(|g| g.region == *n))
            })
            .collect();
        let ymax = rows
            .iter()
            .flat_map(|r| r.regions.iter().map(|g| g.distance.mean))
            .fold(2.2f64, f64::max)
            * 1.15;
        let n = names.len().max(1);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{case}: mean distance to the volumetric reference per facial region"),
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n as f64, 0.0..ymax)?;
        let labels = names.clone();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * n + 1)
            .x_label_formatter(&move |x| {
                let f = x - x.floor();
                if (f - 0.5).abs() < 0.01 {
                    labels
                        .get(x.floor() as usize)
                        .map_or(String::new(), |s| s.to_string())
                } else {
                    String::new()
                }
            })
            .y_desc("mean distance (mm)")
            .draw()?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, 0.6), (n as f64, 0.9)],
                RGBColor(44, 160, 44).mix(0.15).filled(),
            )))?
            .label("clinical tools' mean error 0.6–0.9 mm")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 18, y + 5)],
                    RGBColor(44, 160, 44).mix(0.3).filled(),
                )
            });
        chart
            .draw_series(DashedLineSeries::new(
                vec![(0.0, 2.0), (n as f64, 2.0)],
                8,
                5,
                RED.stroke_width(2),
            ))?
            .label("2 mm: clinically acceptable")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RED.stroke_width(2)));
        let w = 0.8 / rows.len().max(1) as f64;
        for (i, r) in rows.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let bars: Vec<Rectangle<(f64, f64)>> = names
                .iter()
                .enumerate()
                .filter_map(|(k, name)| {
                    let g = r.regions.iter().find(|g| g.region == *name)?;
                    let x0 = k as f64 + 0.1 + i as f64 * w;
                    Some(Rectangle::new(
                        [(x0, 0.0), (x0 + w * 0.9, g.distance.mean)],
                        color.filled(),
                    ))
                })
                .collect();
            chart
                .draw_series(bars)?
                .label(format!("{} ({})", r.method, r.resolution))
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 18, y + 5)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
        Ok(())
    }
    both(dir, stem, (1200, 650), &|r| draw(r, case, rows), &|r| {
        draw(r, case, rows)
    })
}

/// The C1 calibration: mean distance to the reference against k_c (log), struts on and off,
/// the default and the fitted value marked.
pub fn calibration(dir: &Path, stem: &str, c: &super::face::Calibration) -> Result<()> {
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, Shift>,
        c: &super::face::Calibration,
    ) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let pts: Vec<(f64, f64, bool)> = c
            .evaluations
            .iter()
            .filter_map(|e| e.mean_mm.map(|m| (e.k_c, m, e.struts)))
            .collect();
        let (x0, x1) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
            (a.min(p.0), b.max(p.0))
        });
        let (y0, y1) = pts.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        });
        let (x0, x1, y0, y1) = if pts.is_empty() {
            (1e-7, 1e-5, 0.1, 10.0)
        } else {
            (x0 / 1.5, x1 * 1.5, y0 / 1.3, y1 * 1.3)
        };
        let ((xb, xl), (yb, yl)) = (log_ticks(x0, x1), log_ticks(y0, y1));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!(
                    "{}: C1 equilibrium vs the volumetric reference — k_c {:.2e} ({}) → {:.3} mm",
                    c.case,
                    c.k_c,
                    if c.struts { "struts" } else { "no struts" },
                    c.mean_mm
                ),
                ("sans-serif", 17),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0..x1)
                    .log_scale()
                    .with_key_points(xb)
                    .with_light_points(xl),
                (y0..y1)
                    .log_scale()
                    .with_key_points(yb)
                    .with_light_points(yl),
            )?;
        chart
            .configure_mesh()
            .x_desc("k_c (spring stiffness per unit c per mm²)")
            .y_desc("mean distance to reference (mm)")
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| log_tick_label(*v))
            .draw()?;
        for (i, struts) in [true, false].into_iter().enumerate() {
            let color = PALETTE[i];
            let mut line: Vec<(f64, f64)> = pts
                .iter()
                .filter(|p| p.2 == struts)
                .map(|p| (p.0, p.1))
                .collect();
            line.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(line.clone(), color.stroke_width(2)))?
                .label(if struts { "struts on" } else { "struts off" })
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(line.iter().map(|p| Circle::new(*p, 4, color.filled())))?;
        }
        chart
            .draw_series(std::iter::once(Cross::new(
                (c.k_c_default, c.mean_default_mm),
                9,
                BLACK.stroke_width(2),
            )))?
            .label("default")
            .legend(|(x, y)| Cross::new((x + 9, y), 6, BLACK.stroke_width(2)));
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (c.k_c, c.mean_mm),
                9,
                RED.filled(),
            )))?
            .label("calibrated")
            .legend(|(x, y)| TriangleMarker::new((x + 9, y), 6, RED.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
        Ok(())
    }
    both(dir, stem, (1000, 650), &|r| draw(r, c), &|r| draw(r, c))
}

/// Log-log lines (size, seconds), one per labelled series.
pub fn loglog(
    dir: &Path,
    stem: &str,
    title: &str,
    xlabel: &str,
    lines: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, Shift>,
        title: &str,
        xlabel: &str,
        lines: &[(String, Vec<(f64, f64)>)],
    ) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let all: Vec<(f64, f64)> = lines
            .iter()
            .flat_map(|l| l.1.iter().copied())
            .filter(|p| p.0 > 0.0 && p.1 > 0.0)
            .collect();
        let (x0, x1, y0, y1) = all.iter().fold(
            (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
            |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
        );
        let (x0, x1, y0, y1) = if all.is_empty() {
            (1.0, 10.0, 1e-3, 1.0)
        } else {
            (x0 / 1.3, x1 * 1.3, y0 / 2.0, y1 * 2.0)
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0..x1).log_scale(),
                (y0..y1)
                    .log_scale()
                    .with_key_points(log_ticks(y0, y1).0)
                    .with_light_points(log_ticks(y0, y1).1),
            )?;
        chart
            .configure_mesh()
            .x_desc(xlabel)
            .y_desc("wall time (s)")
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| log_tick_label(*v))
            .draw()?;
        for (i, (label, pts)) in lines.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = pts
                .iter()
                .copied()
                .filter(|p| p.0 > 0.0 && p.1 > 0.0)
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        root.present()?;
        Ok(())
    }
    both(
        dir,
        stem,
        (1000, 700),
        &|r| draw(r, title, xlabel, lines),
        &|r| draw(r, title, xlabel, lines),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_tick_labels_are_readable_below_one() {
        // The old "{v:.2}" gave "0.00" for the first two and "0.01" for 0.005.
        let cases = [
            (0.001, "0.001"),
            (0.002, "0.002"),
            (0.005, "0.005"),
            (0.01, "0.01"),
            (10f64.powi(-1), "0.1"),
            (2.0 * 10f64.powi(-1), "0.2"),
            (0.5, "0.5"),
            (1.0, "1"),
            (2.0, "2"),
            (20.0, "20"),
            (100.0, "100"),
        ];
        for (v, want) in cases {
            assert_eq!(log_tick_label(v), want, "{v}");
        }
    }

    #[test]
    fn log_ticks_label_a_range_below_one_millimetre() {
        // The study's phantom chart: 0.2 to 4 mm (plotters labelled only 1 in it).
        let (bold, light) = log_ticks(0.2, 4.0);
        let labels: Vec<String> = bold.iter().map(|&v| log_tick_label(v)).collect();
        assert_eq!(labels, ["0.2", "0.5", "1", "2"]);
        assert_eq!(light.len(), 12);
        let (bold, _) = log_ticks(0.003, 0.08);
        let labels: Vec<String> = bold.iter().map(|&v| log_tick_label(v)).collect();
        assert_eq!(labels, ["0.005", "0.01", "0.02", "0.05"]);
        // Within one decade every digit is labelled; over many only the powers of ten.
        assert_eq!(log_ticks(0.25, 0.95).0.len(), 7);
        assert_eq!(log_ticks(0.9e-3, 1.1e3).0.len(), 7);
    }
}
