//! validation.svg: per surgery and soft landmark, the published range of the soft/hard ratio as a
//! grey bar and each case's predicted ratio as a point over it, its band as a line through the
//! point (a cross when outside the range). Real heads are squares, triangles and diamonds in
//! strong colours, the phantoms circles in muted ones, each head once in the legend.
//! `facesim validate` draws it from the rows `facesim_validate::validate` returns.

use crate::sweep::{DrawResult, FONT};
use facesim::error::{Error, Result};
use facesim::landmarks::published::Verdict;
use facesim::output::write_atomic;
use facesim_validate::validate::Validation;
use plotters::coord::types::RangedCoordf64;
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

/// Real heads' colours: strong, and none of them the phantoms'.
const REAL_COLOURS: [RGBColor; 3] = [
    RGBColor(0, 0, 0),
    RGBColor(230, 120, 0),
    RGBColor(150, 0, 150),
];

/// The phantoms' colours: muted blues and greens.
const PHANTOM_COLOURS: [RGBColor; 6] = [
    RGBColor(70, 130, 180),
    RGBColor(60, 160, 110),
    RGBColor(100, 110, 200),
    RGBColor(40, 170, 170),
    RGBColor(120, 160, 60),
    RGBColor(90, 90, 160),
];

/// A case's marker: circles for phantoms, a square or a triangle for each real head.
#[derive(Clone, Copy)]
enum Marker {
    Circle,
    Square,
    Triangle,
}

impl Marker {
    /// The marker of the `k`-th real head.
    fn real(k: usize) -> Marker {
        [Marker::Square, Marker::Triangle][k % 2]
    }
}

/// The chart being drawn.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// `points` of one case in its marker and colour, once in the legend as `label`.
fn draw_marked(
    chart: &mut Chart,
    marker: Marker,
    points: &[(f64, f64)],
    c: RGBColor,
    label: String,
) -> DrawResult {
    let style = c.filled();
    let at = points.iter().copied();
    match marker {
        Marker::Circle => chart
            .draw_series(at.map(|p| Circle::new(p, 4, style)))?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, style)),
        Marker::Square => chart
            .draw_series(
                at.map(|p| EmptyElement::at(p) + Rectangle::new([(-5, -5), (5, 5)], style)),
            )?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x + 3, y - 5), (x + 13, y + 5)], style)),
        Marker::Triangle => chart
            .draw_series(at.map(|p| TriangleMarker::new(p, 7, style)))?
            .label(label)
            .legend(move |(x, y)| TriangleMarker::new((x + 8, y), 7, style)),
    };
    Ok(())
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
    // One entry per head: a phantom built in two skeletal classes is still one head.
    let mut cases: Vec<(&str, bool)> = Vec::new();
    for c in &v.cases {
        if !cases.iter().any(|(n, _)| *n == c.name) {
            cases.push((c.name.as_str(), c.real_ct));
        }
    }
    let mut phantoms_seen = 0;
    let mut reals_seen = 0;
    for (k, &(case, real)) in cases.iter().enumerate() {
        // Real heads: each its own marker shape in a strong colour; phantoms: circles in muted
        // shades, so a reviewer tells the independent real evidence from the synthetic at a
        // glance.
        let (c, marker) = if real {
            reals_seen += 1;
            (
                REAL_COLOURS[(reals_seen - 1) % REAL_COLOURS.len()],
                Marker::real(reals_seen - 1),
            )
        } else {
            phantoms_seen += 1;
            (
                PHANTOM_COLOURS[(phantoms_seen - 1) % PHANTOM_COLOURS.len()],
                Marker::Circle,
            )
        };
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
            .filter(|r| r.case == case)
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
        let label = if real {
            format!("{case} (real CT)")
        } else {
            format!("{case} (phantom)")
        };
        let xy: Vec<(f64, f64)> = pts.iter().map(|&(x, y, _, _)| (x, y)).collect();
        draw_marked(&mut chart, marker, &xy, c, label)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use facesim::landmarks::published::PUBLISHED;
    use facesim_validate::validate::{CaseInfo, Row, SkeletalClass};

    fn case(name: &str, real_ct: bool, class: Option<SkeletalClass>) -> CaseInfo {
        CaseInfo {
            name: name.into(),
            about: String::new(),
            pitch_deg: 0.0,
            forward: [0.0, -1.0, 0.0],
            up: [0.0, 0.0, 1.0],
            frame_why: String::new(),
            segments: Vec::new(),
            autorotation: Ok(()),
            class,
            real_ct,
            seconds: 0.0,
        }
    }

    fn row(case: &str, k: usize, ratio: f64) -> Row {
        Row {
            case: case.into(),
            published: &PUBLISHED[k],
            move_mm: 5.0,
            along_mm: Some(5.0 * ratio),
            forward_mm: None,
            up_mm: None,
            ratio: Some(ratio),
            tissue_band: Some([ratio - 0.05, ratio + 0.05]),
            coarse_mesh: Some(ratio + 0.01),
            band: Some([ratio - 0.05, ratio + 0.05]),
            why: None,
        }
    }

    /// A reviewer tells the real heads from the phantoms at a glance: each real head has a
    /// marker shape of its own, every head is in the legend once (a phantom built in two
    /// skeletal classes too), and each band is a line.
    #[test]
    fn real_heads_have_their_own_markers_and_each_head_is_in_the_legend_once() {
        let v = Validation {
            rows: vec![
                row("real", 0, 0.3),
                row("real-mandible", 0, 0.5),
                row("phantom01", 0, 0.4),
                row("phantom01", 1, 0.5),
            ],
            skipped: Vec::new(),
            cases: vec![
                case("real", true, None),
                case("real-mandible", true, None),
                case("phantom01", false, Some(SkeletalClass::III)),
                case("phantom01", false, Some(SkeletalClass::II)),
            ],
            out_dir: std::env::temp_dir(),
        };
        let dir = std::env::temp_dir().join(format!("facesim-chart-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("validation.svg");
        write(&path, &v).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let count = |s: &str| svg.matches(s).count();
        assert_eq!(count("real (real CT)"), 1, "{svg}");
        assert_eq!(count("real-mandible (real CT)"), 1);
        assert_eq!(count("phantom01 (phantom)"), 1);
        // The first real head's squares (its point and its legend entry) in black, the second's
        // triangles in orange, the phantom's circles in its muted blue.
        assert_eq!(
            count(r##"height="10" opacity="1" fill="#000000""##),
            2,
            "{svg}"
        );
        assert_eq!(
            count(r##"<polygon opacity="1" fill="#E67800""##),
            2,
            "{svg}"
        );
        assert_eq!(count(r##"fill="#4682B4""##), 3, "{svg}");
    }
}
