//! SVG plots for reports (plotters, SVG backend only: no system font or image libraries).
//!
//! Output only: each function writes one file and returns a typed error naming it.

use std::path::Path;

use plotters::prelude::*;

/// A plot could not be drawn or written.
#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {message}")]
pub struct PlotError {
    /// The file.
    pub path: String,
    /// What went wrong.
    pub message: String,
}

fn err(path: &Path, e: impl std::fmt::Display) -> PlotError {
    PlotError {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Colour of a value in `[0, 1]` on a blue → red ramp.
fn ramp(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    RGBColor(
        (40.0 + 215.0 * t) as u8,
        (80.0 + 60.0 * (1.0 - (2.0 * t - 1.0).abs())) as u8,
        (255.0 * (1.0 - t)) as u8,
    )
}

/// Scatter of `(x, y, value)` points coloured by value, with the value range in the caption.
/// `x`, `y` in metres; `unit` names the value's unit.
pub fn scatter_heat(
    path: &Path,
    title: &str,
    points: &[(f64, f64, f64)],
    unit: &str,
) -> Result<(), PlotError> {
    if points.is_empty() {
        return Err(err(path, "no points to plot"));
    }
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    let (mut v0, mut v1) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y, v) in points {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
        v0 = v0.min(v);
        v1 = v1.max(v);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1e-3);
    let root = SVGBackend::new(path, (720, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let caption = format!("{title}  (colour: {v0:.4} {unit} blue … {v1:.4} {unit} red)");
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d((x0 - pad)..(x1 + pad), (y0 - pad)..(y1 + pad))
        .map_err(|e| err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc("y [m]")
        .draw()
        .map_err(|e| err(path, e))?;
    let span = (v1 - v0).max(1e-300);
    chart
        .draw_series(
            points
                .iter()
                .map(|&(x, y, v)| Circle::new((x, y), 4, ramp((v - v0) / span).filled())),
        )
        .map_err(|e| err(path, e))?;
    root.present().map_err(|e| err(path, e))?;
    Ok(())
}

/// Points of several labelled series on one chart (`x`, `y` in the given units), each
/// series in its own colour with a legend. The y range always includes 0.
pub fn series(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    data: &[(String, Vec<(f64, f64)>)],
) -> Result<(), PlotError> {
    let pts = data.iter().flat_map(|(_, v)| v.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64, 0.0f64);
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let pad = (0.05 * (x1 - x0)).max(1e-9);
    if !x0.is_finite() {
        return Err(err(path, "no points to plot"));
    }
    let root = SVGBackend::new(path, (900, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((x0 - pad)..(x1 + pad), (y0 * 1.1)..(y1 * 1.1).max(1e-9))
        .map_err(|e| err(path, e))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()
        .map_err(|e| err(path, e))?;
    for (k, (label, v)) in data.iter().enumerate() {
        let c = Palette99::pick(k).to_rgba();
        chart
            .draw_series(v.iter().map(|&(x, y)| Circle::new((x, y), 3, c.filled())))
            .map_err(|e| err(path, e))?
            .label(label.as_str())
            .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(path, e))?;
    root.present().map_err(|e| err(path, e))?;
    Ok(())
}
