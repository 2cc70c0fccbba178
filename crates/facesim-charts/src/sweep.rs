//! sweep.svg: per plan, the face displacement's mean, 90th percentile and max, and each present
//! facial region's mean (mm). `facesim sweep` and the Python module's `sweep(out=…)` draw it
//! from the rows `facesim::commands::sweep` returns. The font and palette are the other charts'
//! too.

use facesim::commands::sweep::{REGION_NAMES, SweepRow};
use facesim::error::{Error, Result};
use facesim::output::write_atomic;
use plotters::prelude::*;
use std::path::Path;

/// The charts' font and colours, shared with validation.svg and the lab's study charts.
pub static FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

pub type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// The lines of the chart: (name, value per plan).
fn series(rows: &[SweepRow]) -> Vec<(String, Vec<f64>)> {
    let mut s = vec![
        (
            "face max".to_string(),
            rows.iter().map(|r| r.face.max).collect(),
        ),
        (
            "face p90".to_string(),
            rows.iter().map(|r| r.face.p90).collect(),
        ),
        (
            "face mean".to_string(),
            rows.iter().map(|r| r.face.mean).collect(),
        ),
    ];
    for (i, name) in REGION_NAMES.iter().enumerate() {
        if rows
            .iter()
            .all(|r| r.regions.get(i).is_some_and(|x| x.is_some()))
        {
            s.push((
                format!("{name} mean"),
                rows.iter()
                    .map(|r| r.regions[i].map_or(0.0, |x| x.mean))
                    .collect(),
            ));
        }
    }
    s
}

fn draw(root: DrawingArea<SVGBackend, plotters::coord::Shift>, rows: &[SweepRow]) -> DrawResult {
    root.fill(&WHITE)?;
    let lines = series(rows);
    let top = lines
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .fold(0.0, f64::max)
        .max(1e-3)
        * 1.1;
    let n = rows.len().max(2);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Face displacement per plan (plan basis)",
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(1.0..n as f64, 0.0..top)?;
    chart
        .configure_mesh()
        .x_desc("plan (sweep.csv row)")
        .y_desc("displacement (mm)")
        .draw()?;
    for (i, (name, v)) in lines.iter().enumerate() {
        let c = PALETTE[i % PALETTE.len()];
        chart
            .draw_series(LineSeries::new(
                v.iter().enumerate().map(|(j, y)| ((j + 1) as f64, *y)),
                c.stroke_width(2),
            ))?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Write the chart of `rows` to `path` (SVG, atomically).
pub fn write(path: &Path, rows: &[SweepRow]) -> Result<()> {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
    write_atomic(path, |tmp| {
        let root = SVGBackend::new(tmp, (900, 540)).into_drawing_area();
        draw(root, rows).map_err(|e| Error::output(path, e.to_string()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use facesim::commands::sweep::{Stats, SweepPlan};

    #[test]
    fn the_chart_draws_the_face_lines_and_the_regions_every_plan_has() {
        let s = |m: f64| Stats {
            max: m,
            mean: m / 2.0,
            p90: m * 0.9,
        };
        let rows: Vec<SweepRow> = (0..3)
            .map(|i| SweepRow {
                plan: SweepPlan {
                    label: format!("plan {i}"),
                    osteotomy: vec![],
                },
                face: s(i as f64),
                // The first region in every row, the second in one row only.
                regions: vec![Some(s(1.0)), (i == 0).then(|| s(2.0))],
                landmarks: vec![],
                measurements: vec![],
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sweep.svg");
        write(&path, &rows).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("face max"));
        assert!(svg.contains(&format!("{} mean", REGION_NAMES[0])));
        assert!(!svg.contains(&format!("{} mean", REGION_NAMES[1])));
    }
}
