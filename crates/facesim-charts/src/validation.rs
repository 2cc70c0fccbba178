//! validation.svg: per surgery and soft landmark, the published range of the soft/hard ratio as a
//! grey bar and each case's predicted ratio as a point over it, its band as a line through the
//! point (a cross when outside the range).
//! `facesim validate` draws it from the rows `facesim_validate::validate` returns.

use crate::sweep::{DrawResult, FONT, PALETTE};
use facesim::error::{Error, Result};
use facesim::landmarks::published::Verdict;
use facesim::output::write_atomic;
use facesim_validate::validate::Validation;
use plotters::prelude::*;
use std::path::Path;

/// The chart's lines: (surgery, soft landmark, low, high), in table order, those with a ratio.
fn lines(v: &Validation) -> Vec<(String, f64, f64)> {
    let mut out: Vec<(String, f64, f64)> = Vec::new();
    for r in &v.rows {
        let p = r.published;
        let name = format!("{}: {} ({})", p.surgery.key(), p.soft, p.axis.name());
        if p.unmeasured.is_none() && !out.iter().any(|(n, _, _)| *n == name) {
            out.push((name, p.low, p.high));
        }
    }
    out
}

fn draw(root: DrawingArea<SVGBackend, plotters::coord::Shift>, v: &Validation) -> DrawResult {
    root.fill(&WHITE)?;
    let lines = lines(v);
    let n = lines.len().max(1);
    let hi = v
        .rows
        .iter()
        .filter_map(|r| r.band.map(|b| b[1]).or(r.ratio))
        .chain(lines.iter().map(|l| l.2))
        .fold(1.4f64, f64::max)
        + 0.1;
    let lo = v
        .rows
        .iter()
        .filter_map(|r| r.band.map(|b| b[0]).or(r.ratio))
        .fold(0.0f64, f64::min)
        - 0.1;
    let names: Vec<String> = lines.iter().map(|l| l.0.clone()).collect();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Predicted soft/hard ratio per case (points, with the band as a line; red cross: outside) over the published range (grey; a dark tick: one published value)",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(300)
        .build_cartesian_2d(lo..hi, (n as f64 - 0.5)..-0.5)?;
    chart
        .configure_mesh()
        .y_labels(n + 1)
        .y_label_formatter(&|y: &f64| {
            let i = y.round();
            if (y - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[i as usize].clone()
            } else {
                String::new()
            }
        })
        .x_desc("soft displacement along the move ÷ the bone's move")
        .draw()?;
    // A published range as a grey bar; one published value (one study, or "≈ x") as a dark
    // tick the width of the table's printed precision (0.01), not a range it does not print.
    chart.draw_series(lines.iter().enumerate().map(|(i, (_, l, h))| {
        let (l, h, colour) = if l == h {
            (l - 5e-3, h + 5e-3, RGBColor(90, 90, 90))
        } else {
            (*l, *h, RGBColor(200, 200, 200))
        };
        Rectangle::new(
            [(l, i as f64 - 0.35), (h, i as f64 + 0.35)],
            colour.filled(),
        )
    }))?;
    let cases: Vec<&str> = v.cases.iter().map(|c| c.name.as_str()).collect();
    for (k, case) in cases.iter().enumerate() {
        let c = PALETTE[k % PALETTE.len()];
        // Each case on its own height within the line, so coincident points stay visible.
        let dy = if cases.len() > 1 {
            -0.3 + 0.6 * k as f64 / (cases.len() - 1) as f64
        } else {
            0.0
        };
        // (ratio, height, not outside, band)
        type Point = (f64, f64, bool, Option<[f64; 2]>);
        let pts: Vec<Point> = v
            .rows
            .iter()
            .filter(|r| r.case == *case)
            .filter_map(|r| {
                let p = r.published;
                let name = format!("{}: {} ({})", p.surgery.key(), p.soft, p.axis.name());
                let i = lines.iter().position(|l| l.0 == name)?;
                let outside = r.verdict() == Some(Verdict::Outside);
                Some((r.ratio?, i as f64 + dy, !outside, r.band))
            })
            .collect();
        // The band: the tissue parameters' p05–p95 with the mesh's difference.
        chart.draw_series(pts.iter().filter_map(|&(_, y, _, b)| {
            let [l, h] = b?;
            Some(PathElement::new(vec![(l, y), (h, y)], c.stroke_width(2)))
        }))?;
        chart
            .draw_series(
                pts.iter()
                    .map(|&(x, y, _, _)| Circle::new((x, y), 4, c.filled())),
            )?
            .label(*case)
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, c.filled()));
        chart.draw_series(
            pts.iter()
                .filter(|p| !p.2)
                .map(|&(x, y, _, _)| Cross::new((x, y), 7, RED.stroke_width(2))),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Write the chart of `v` to `path` (SVG, atomically).
pub fn write(path: &Path, v: &Validation) -> Result<()> {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
    let height = 140 + 26 * lines(v).len() as u32;
    write_atomic(path, |tmp| {
        let root = SVGBackend::new(tmp, (1100, height)).into_drawing_area();
        draw(root, v).map_err(|e| Error::output(path, e.to_string()))
    })
}
