//! SVG figures of the real-data results (plotters), written atomically.
use anyhow::{anyhow, Result};
use motorid::report::svg::colour;
use plotters::prelude::*;
use std::path::Path;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    Line,
    Dots,
}

/// One series of a figure.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text; empty: no legend entry (e.g. the second branch of a curve).
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
    /// Index into the palette ([`colour`]).
    pub color: usize,
}

impl Series {
    pub fn line(label: &str, points: Vec<(f64, f64)>, color: usize) -> Series {
        Series {
            label: label.to_string(),
            points,
            style: Style::Line,
            color,
        }
    }

    pub fn dots(label: &str, points: Vec<(f64, f64)>, color: usize) -> Series {
        Series {
            label: label.to_string(),
            points,
            style: Style::Dots,
            color,
        }
    }
}

fn range(series: &[Series], f: impl Fn(&(f64, f64)) -> f64) -> (f64, f64) {
    let (lo, hi) = series
        .iter()
        .flat_map(|s| s.points.iter().map(&f))
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
        return (lo - 1.0, lo + 1.0);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Draw `series` into an SVG file at `path` (atomic write).
pub fn figure(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[Series],
) -> Result<()> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 480)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| anyhow!("{}: cannot draw: {e}", path.display());
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let (x0, x1) = range(series, |p| p.0);
        let (y0, y1) = range(series, |p| p.1);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(xlabel)
            .y_desc(ylabel)
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(|e| err(&e))?;
        for s in series {
            let c = colour(s.color);
            match s.style {
                Style::Line => {
                    let ann = chart
                        .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
                        .map_err(|e| err(&e))?;
                    if !s.label.is_empty() {
                        ann.label(s.label.clone()).legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                        });
                    }
                }
                Style::Dots => {
                    let ann = chart
                        .draw_series(
                            s.points
                                .iter()
                                .map(|&(x, y)| Circle::new((x, y), 3, c.filled())),
                        )
                        .map_err(|e| err(&e))?;
                    if !s.label.is_empty() {
                        ann.label(s.label.clone())
                            .legend(move |(x, y)| Circle::new((x + 9, y), 3, c.filled()));
                    }
                }
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    motorid::atomic::write_str(path, &svg)
}

/// Every `step`-th point of a time series (figures need no 25 000 points).
pub fn thin(t: &[f64], y: &[f64], step: usize) -> Vec<(f64, f64)> {
    t.iter()
        .zip(y)
        .step_by(step.max(1))
        .map(|(&a, &b)| (a, b))
        .collect()
}
