//! PNG charts of error against cost, drawn with plotters.

use anyhow::{Context, Result};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// One measured setting.
#[derive(Debug, Clone)]
pub struct Point {
    /// Wall-clock seconds.
    pub cost: f64,
    /// Error in percent.
    pub error: f64,
    pub label: String,
}

/// Fonts tried in order after `$MESHLESS_FONT`.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

/// Registers a TrueType font for plotters once; false when none is found.
fn font() -> bool {
    static FOUND: OnceLock<bool> = OnceLock::new();
    *FOUND.get_or_init(|| {
        let env = std::env::var("MESHLESS_FONT").ok();
        env.iter()
            .map(String::as_str)
            .chain(FONT_PATHS.iter().copied())
            .filter_map(|path| std::fs::read(path).ok())
            .any(|bytes| {
                // plotters keeps fonts for the life of the process.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok()
            })
    })
}

/// Draws `points` as error (y, described by `y_desc`) against cost (x),
/// each labelled. Returns false, drawing nothing, when no font is
/// available for the text.
///
/// # Errors
/// When the PNG cannot be written.
fn error_against_cost(path: &Path, title: &str, y_desc: &str, points: &[Point]) -> Result<bool> {
    if !font() {
        return Ok(false);
    }
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let max_cost = points.iter().map(|p| p.cost).fold(0.0, f64::max).max(1e-3) * 1.15;
        let max_error = points.iter().map(|p| p.error).fold(0.0, f64::max).max(1.0) * 1.2;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..max_cost, 0.0..max_error)?;
        chart
            .configure_mesh()
            .x_desc("wall-clock time [s]")
            .y_desc(y_desc)
            .label_style(("sans-serif", 15))
            .draw()?;
        chart.draw_series(
            points
                .iter()
                .map(|p| Circle::new((p.cost, p.error), 6, BLUE.filled())),
        )?;
        chart.draw_series(points.iter().map(|p| {
            Text::new(
                p.label.clone(),
                (p.cost, p.error + 0.03 * max_error),
                ("sans-serif", 16),
            )
        }))?;
        root.present()?;
        Ok(())
    };
    draw()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("cannot draw {}", path.display()))?;
    Ok(true)
}

/// Writes a study's CSV table to `path` and says where.
///
/// # Errors
/// When the file cannot be written.
pub fn write_table(path: &Path, csv: &str) -> Result<()> {
    std::fs::write(path, csv).with_context(|| format!("cannot write {}", path.display()))?;
    outln!("  table             {}", path.display())?;
    Ok(())
}

/// `error_against_cost`, then says where the chart went, or why none
/// was drawn.
///
/// # Errors
/// When the PNG or the line cannot be written.
pub fn draw_and_report(path: &Path, title: &str, y_desc: &str, points: &[Point]) -> Result<()> {
    if error_against_cost(path, title, y_desc, points)? {
        outln!("  chart             {}", path.display())?;
    } else {
        outln!(
            "  chart             not drawn: no TrueType font found (set MESHLESS_FONT to a .ttf file)"
        )?;
    }
    Ok(())
}

/// Draws each named series as a line with markers, `y` against `x`.
/// Returns false, drawing nothing, when no font is available.
fn lines(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    series: &[(&str, Vec<(f64, f64)>)],
) -> Result<bool> {
    if !font() {
        return Ok(false);
    }
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let all = || series.iter().flat_map(|(_, p)| p.iter());
        let x_max = all().map(|p| p.0).fold(0.0, f64::max).max(1e-9) * 1.1;
        let y_min = all().map(|p| p.1).fold(0.0, f64::min);
        let y_max = all().map(|p| p.1).fold(0.0, f64::max);
        let pad = 0.1 * (y_max - y_min).max(1e-9);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(20)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..x_max, (y_min - pad)..(y_max + pad))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style(("sans-serif", 15))
            .draw()?;
        for (k, (name, points)) in series.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    colour.stroke_width(2),
                ))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart.draw_series(points.iter().map(|p| Circle::new(*p, 5, colour.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 16))
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("cannot draw {}", path.display()))?;
    Ok(true)
}

/// `lines`, then says where the chart went, or why none was drawn.
///
/// # Errors
/// When the PNG or the line cannot be written.
pub fn lines_and_report(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[(&str, Vec<(f64, f64)>)],
) -> Result<()> {
    if lines(path, title, (x_desc, y_desc), series)? {
        outln!("  chart             {}", path.display())?;
    } else {
        outln!(
            "  chart             not drawn: no TrueType font found (set MESHLESS_FONT to a .ttf file)"
        )?;
    }
    Ok(())
}
