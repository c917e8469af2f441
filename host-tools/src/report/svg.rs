//! SVG charts drawn with `plotters` into strings, for inline use in the HTML reports: time
//! series, bars, and correlation stems with confidence bands.
use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// Chart size in pixels (width, height): fits a laptop screen two charts high.
pub const SIZE: (u32, u32) = (900, 320);

/// Colours of successive series: the Okabe–Ito palette, told apart with any colour vision
/// deficiency and in greyscale print.
const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 0, 0),
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
];

/// Colour of series `k` (cycling through the palette), for every chart the tool draws.
pub fn colour(k: usize) -> RGBColor {
    PALETTE[k % PALETTE.len()]
}

fn bounds<'a>(it: impl Iterator<Item = &'a f64>) -> (f64, f64) {
    let (lo, hi) = it
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        return (lo - 0.5, hi + 0.5);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Keep at most `max` evenly spaced points (an SVG with 10⁵ points is slow to open).
fn thin(x: &[f64], y: &[f64], max: usize) -> Vec<(f64, f64)> {
    let n = x.len().min(y.len());
    let step = n.div_ceil(max.max(1)).max(1);
    (0..n)
        .step_by(step)
        .filter(|&k| x[k].is_finite() && y[k].is_finite())
        .map(|k| (x[k], y[k]))
        .collect()
}

/// One series of a line chart: (legend, x, y).
pub type Series<'a> = (&'a str, &'a [f64], &'a [f64]);

/// Most points drawn per series.
pub const MAX_POINTS: usize = 4000;

/// Line chart of one or more series.
pub fn line_chart(title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("chart: {e}"))?;
        let (x0, x1) = bounds(series.iter().flat_map(|s| s.1.iter()));
        let (y0, y1) = bounds(series.iter().flat_map(|s| s.2.iter()));
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| anyhow!("chart: {e}"))?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(|e| anyhow!("chart: {e}"))?;
        for (k, (name, x, y)) in series.iter().enumerate() {
            let c = colour(k);
            chart
                .draw_series(LineSeries::new(thin(x, y, MAX_POINTS), c.stroke_width(1)))
                .map_err(|e| anyhow!("chart: {e}"))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        if series.len() > 1 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| anyhow!("chart: {e}"))?;
        }
        root.present().map_err(|e| anyhow!("chart: {e}"))?;
    }
    Ok(out)
}

/// Vertical bar chart with one bar per label.
pub fn bar_chart(title: &str, y_label: &str, labels: &[String], values: &[f64]) -> Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("chart: {e}"))?;
        let n = labels.len().max(1);
        let top = values
            .iter()
            .cloned()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        let top = if top > 0.0 { top * 1.1 } else { 1.0 };
        // One segment per bar, labelled at its centre (plotters' segmented axis: a float
        // axis would put "nice" ticks between the bars and repeat the first label).
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(60)
            .y_label_area_size(70)
            .build_cartesian_2d((0..n).into_segmented(), 0.0..top)
            .map_err(|e| anyhow!("chart: {e}"))?;
        let labels_owned: Vec<String> = labels.to_vec();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n + 1)
            .x_label_formatter(&|x| match x {
                SegmentValue::CenterOf(k) => labels_owned.get(*k).cloned().unwrap_or_default(),
                _ => String::new(),
            })
            .y_desc(y_label)
            .draw()
            .map_err(|e| anyhow!("chart: {e}"))?;
        chart
            .draw_series(values.iter().enumerate().map(|(k, v)| {
                let v = if v.is_finite() { *v } else { 0.0 };
                let mut bar = Rectangle::new(
                    [
                        (SegmentValue::Exact(k), 0.0),
                        (SegmentValue::Exact(k + 1), v),
                    ],
                    colour(0).filled(),
                );
                bar.set_margin(0, 0, 12, 12);
                bar
            }))
            .map_err(|e| anyhow!("chart: {e}"))?;
        root.present().map_err(|e| anyhow!("chart: {e}"))?;
    }
    Ok(out)
}

/// Correlation stems over lags with a ±`band` confidence band (as MATLAB's `resid`).
pub fn correlation_chart(title: &str, lags: &[f64], values: &[f64], band: f64) -> Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("chart: {e}"))?;
        let (x0, x1) = bounds(lags.iter());
        let m = values.iter().fold(band, |a, v| a.max(v.abs())).max(1e-6) * 1.1;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, -m..m)
            .map_err(|e| anyhow!("chart: {e}"))?;
        chart
            .configure_mesh()
            .x_desc("lag (samples)")
            .y_desc("correlation")
            .draw()
            .map_err(|e| anyhow!("chart: {e}"))?;
        for b in [band, -band] {
            chart
                .draw_series(LineSeries::new(
                    vec![(x0, b), (x1, b)],
                    colour(1).stroke_width(1),
                ))
                .map_err(|e| anyhow!("chart: {e}"))?;
        }
        chart
            .draw_series(lags.iter().zip(values).map(|(l, v)| {
                PathElement::new(vec![(*l, 0.0), (*l, *v)], colour(0).stroke_width(2))
            }))
            .map_err(|e| anyhow!("chart: {e}"))?;
        root.present().map_err(|e| anyhow!("chart: {e}"))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_are_svg_with_their_data() {
        let x: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let y: Vec<f64> = x.iter().map(|v| v.sin()).collect();
        let s = line_chart(
            "Velocity",
            "t [s]",
            "ω",
            &[("measured", &x, &y), ("model", &x, &x)],
        )
        .unwrap();
        assert!(s.starts_with("<svg") && s.contains("Velocity") && s.contains("polyline"));
        let b = bar_chart("Error", "rms", &["a".into(), "b".into()], &[1.0, 2.0]).unwrap();
        assert!(b.contains("<rect"));
        // Every bar is labelled once with its own label (not the first label repeated).
        let b = bar_chart(
            "Error",
            "rms",
            &["LuGre".into(), "+offset".into(), "+cogging".into()],
            &[3.0, 2.0, 1.0],
        )
        .unwrap();
        for l in ["LuGre", "+offset", "+cogging"] {
            assert_eq!(b.matches(l).count(), 1, "label {l} in {b}");
        }
        let c = correlation_chart("acf", &[1.0, 2.0], &[0.5, -0.1], 0.05).unwrap();
        assert!(c.contains("<svg"));
    }
}
