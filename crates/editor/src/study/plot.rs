//! The study's charts as PNG, drawn with plotters into a pixel buffer and
//! written by the `image` crate: per-avatar authenticity with the category
//! means (thesis Figures 6.2 and 6.3 in one picture) and per-region scores
//! for edited and unedited regions (Figure 6.4). The font travels with the
//! binary (a DejaVu Sans subset), so plots need nothing from the system.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::analysis::{Analysis, Estimate};
use crate::compose::composition::StudyGroup;
use crate::error::{Error, Result};

/// The font the charts are labelled with (see assets/fonts/README.md).
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");
/// Name the font is registered under.
const FAMILY: &str = "visage-sans";

/// Colours per category (blues first for the thesis's unedited categories,
/// which come first in its tables), then per region.
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(116, 173, 209),
    RGBColor(230, 85, 13),
    RGBColor(253, 141, 60),
    RGBColor(253, 190, 133),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// A labelled group of bars: each bar's label, estimate (a gap when
/// missing) and colour.
type BarGroup = (String, Vec<(String, Option<Estimate>, RGBColor)>);

fn plot_error(e: impl std::fmt::Display) -> Error {
    Error::input(format!("cannot draw the plot: {e}"))
}

fn register_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    ok.then_some(())
        .ok_or_else(|| Error::input("the bundled plot font is unreadable"))
}

/// Draws into a fresh white canvas and writes it as PNG.
fn draw_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Area) -> std::result::Result<(), Box<dyn std::error::Error>>,
) -> Result<()> {
    register_font()?;
    let mut pixels = vec![255u8; (size.0 * size.1 * 3) as usize];
    {
        let area = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        draw(&area).map_err(plot_error)?;
        area.present().map_err(plot_error)?;
    }
    let image = image::RgbImage::from_raw(size.0, size.1, pixels).expect("buffer matches size");
    image.save(path).map_err(|e| Error::io("write", path, e))
}

fn category_colour(analysis: &Analysis, name: &str) -> RGBColor {
    let i = analysis
        .categories
        .iter()
        .position(|c| c.category == name)
        .unwrap_or(0);
    PALETTE[i % PALETTE.len()]
}

/// Writes `authenticity.png` and `regions.png` into `dir`; returns their paths.
pub fn write_plots(analysis: &Analysis, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
    let scores = dir.join("authenticity.png");
    draw_png(&scores, (1400, 900), |area| {
        authenticity_chart(area, analysis)
    })?;
    let regions = dir.join("regions.png");
    draw_png(&regions, (1400, 600), |area| regions_chart(area, analysis))?;
    Ok(vec![scores, regions])
}

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// Height of a labelled grid's header band, in pixels.
const GRID_HEADER: u32 = 22;
/// Width of a labelled grid's row-label band, in pixels.
const GRID_LABELS: u32 = 150;

/// Pictures in a labelled grid: `columns` pictures per row under the
/// column titles, each row named on its left (e.g. an evaluation's render
/// beside its ground truth, per held-out view).
pub fn labelled_grid(
    images: &[crate::render::image::RgbImage],
    columns: &[&str],
    row_labels: &[String],
) -> Result<crate::render::image::RgbImage> {
    register_font()?;
    let cols = columns.len().max(1) as u32;
    let (w, h) = images.first().map_or((1, 1), |i| (i.width, i.height));
    let rows = (images.len() as u32).div_ceil(cols);
    let size = (GRID_LABELS + cols * w, GRID_HEADER + rows * h);
    let mut pixels = vec![255u8; (size.0 * size.1 * 3) as usize];
    for (k, img) in images.iter().enumerate() {
        let (ox, oy) = (
            GRID_LABELS + (k as u32 % cols) * w,
            GRID_HEADER + (k as u32 / cols) * h,
        );
        for y in 0..img.height.min(h) {
            for x in 0..img.width.min(w) {
                let src = ((y * img.width + x) * 3) as usize;
                let dst = (((oy + y) * size.0 + ox + x) * 3) as usize;
                pixels[dst..dst + 3].copy_from_slice(&img.pixels[src..src + 3]);
            }
        }
    }
    {
        let area = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        let style = (FAMILY, 13).into_font().color(&BLACK);
        for (c, title) in columns.iter().enumerate() {
            let x = (GRID_LABELS + c as u32 * w + 4) as i32;
            area.draw(&Text::new(title.to_string(), (x, 3), style.clone()))
                .map_err(plot_error)?;
        }
        for (r, label) in row_labels.iter().enumerate().take(rows as usize) {
            let y = (GRID_HEADER + r as u32 * h + h / 2) as i32 - 8;
            area.draw(&Text::new(label.clone(), (4, y), style.clone()))
                .map_err(plot_error)?;
        }
        area.present().map_err(plot_error)?;
    }
    Ok(crate::render::image::RgbImage {
        width: size.0,
        height: size.1,
        pixels,
    })
}

/// Top: one bar per avatar (sorted by score within its category; excluded
/// avatars faded). Bottom: category means with their intervals, before and
/// after exclusion.
fn authenticity_chart(area: &Area, analysis: &Analysis) -> DrawResult {
    let (top, bottom) = area.split_vertically(560);
    let mut bars: Vec<_> = analysis
        .avatars
        .iter()
        .filter(|a| !analysis.unanswered.contains(&a.id))
        .collect();
    let rank = |c: &str| analysis.categories.iter().position(|k| k.category == c);
    bars.sort_by(|a, b| {
        rank(&a.category)
            .cmp(&rank(&b.category))
            .then(b.authenticity.total_cmp(&a.authenticity))
    });
    let n = bars.len().max(1);
    let ids: Vec<u32> = bars.iter().map(|a| a.id).collect();
    let mut chart = ChartBuilder::on(&top)
        .caption(
            "Authenticity per avatar (share of \"not edited\")",
            (FAMILY, 24),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.5f64..n as f64 - 0.5, 0f64..1.05)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n)
        .x_label_formatter(&|v| label_at(*v, &ids))
        .x_desc("avatar")
        .y_desc("authenticity")
        .label_style((FAMILY, 13))
        .draw()?;
    chart.draw_series(bars.iter().enumerate().map(|(i, a)| {
        let colour = category_colour(analysis, &a.category);
        let style = if a.excluded.is_empty() {
            colour.filled()
        } else {
            faded(colour, 0.3).filled()
        };
        Rectangle::new(
            [(i as f64 - 0.4, 0.0), (i as f64 + 0.4, a.authenticity)],
            style,
        )
    }))?;
    for c in &analysis.categories {
        let colour = category_colour(analysis, &c.category);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(-10.0, -1.0), (-9.0, -0.9)],
                colour.filled(),
            )))?
            .label(c.category.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 12, y + 6)], colour.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FAMILY, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;

    let groups: Vec<BarGroup> = analysis
        .categories
        .iter()
        .map(|c| {
            let colour = category_colour(analysis, &c.category);
            let mut cells = vec![("all".to_string(), c.all, colour)];
            if c.kept.is_some() {
                cells.push(("kept".to_string(), c.kept, faded(colour, 0.55)));
            }
            (c.category.clone(), cells)
        })
        .collect();
    let title = if analysis.categories.iter().any(|c| c.kept.is_some()) {
        "Mean per category (left: all avatars, right: after exclusion), 95% bootstrap CI"
    } else {
        "Mean per category, 95% bootstrap CI"
    };
    grouped_bars(&bottom, title, &groups, false)
}

/// `colour` at `alpha` over the white background, as an opaque colour.
fn faded(colour: RGBColor, alpha: f64) -> RGBColor {
    let over = |c: u8| (c as f64 * alpha + 255.0 * (1.0 - alpha)).round() as u8;
    RGBColor(over(colour.0), over(colour.1), over(colour.2))
}

/// Figure 6.4: per category, the four regions' scores where edited (left)
/// and where not edited (right).
fn regions_chart(area: &Area, analysis: &Analysis) -> DrawResult {
    let (left, right) = area.split_horizontally(700);
    for (panel, edited) in [(&left, true), (&right, false)] {
        let groups: Vec<BarGroup> = analysis
            .categories
            .iter()
            .map(|c| {
                let cells = StudyGroup::EDITABLE
                    .iter()
                    .enumerate()
                    .map(|(i, g)| {
                        let r = analysis
                            .regions
                            .iter()
                            .find(|r| r.category == c.category && r.group == *g);
                        let e = r.and_then(|r| if edited { r.edited } else { r.unedited });
                        (g.name().to_string(), e, PALETTE[(i + 4) % PALETTE.len()])
                    })
                    .collect();
                (c.category.clone(), cells)
            })
            .collect();
        let title = if edited {
            "Regions where edited (whiskers: 95% bootstrap CI)"
        } else {
            "Regions where not edited (whiskers: 95% bootstrap CI)"
        };
        grouped_bars(panel, title, &groups, true)?;
    }
    Ok(())
}

/// Bars in groups along x, each with its interval as a whisker; a missing
/// estimate leaves a gap. With `legend`, the first group's bar labels and
/// colours are named in a legend.
fn grouped_bars(area: &Area, title: &str, groups: &[BarGroup], legend: bool) -> DrawResult {
    let names: Vec<String> = groups.iter().map(|g| g.0.clone()).collect();
    let count = groups.len().max(1);
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(-0.5f64..count as f64 - 0.5, 0f64..1.05)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(count)
        .x_label_formatter(&|v| {
            let i = v.round();
            if (v - i).abs() > 1e-6 || i < 0.0 {
                return String::new();
            }
            names.get(i as usize).cloned().unwrap_or_default()
        })
        .x_desc("category")
        .y_desc("authenticity")
        .label_style((FAMILY, 13))
        .draw()?;
    for (g, (_, cells)) in groups.iter().enumerate() {
        if cells.iter().all(|(_, e, _)| e.is_none()) {
            chart.draw_series(std::iter::once(Text::new(
                "no data".to_string(),
                (g as f64 - 0.15, 0.05),
                (FAMILY, 13),
            )))?;
            continue;
        }
        let width = 0.8 / cells.len().max(1) as f64;
        for (k, (_, estimate, colour)) in cells.iter().enumerate() {
            let Some(e) = estimate else { continue };
            let x0 = g as f64 - 0.4 + k as f64 * width;
            let mid = x0 + width / 2.0;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x0 + 0.01, 0.0), (x0 + width - 0.01, e.mean)],
                colour.filled(),
            )))?;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(mid, e.low), (mid, e.high)],
                BLACK.stroke_width(2),
            )))?;
            chart.draw_series(std::iter::once(Text::new(
                format!("{:.2}", e.mean),
                (x0 + 0.01, (e.high + 0.02).min(1.02)),
                (FAMILY, 12),
            )))?;
        }
    }
    if legend {
        for (label, _, colour) in groups.first().map_or(&[][..], |g| &g.1[..]) {
            let colour = *colour;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(-10.0, -1.0), (-9.0, -0.9)],
                    colour.filled(),
                )))?
                .label(label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 12, y + 6)], colour.filled())
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .label_font((FAMILY, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    Ok(())
}

/// The avatar id at an integer bar position, else nothing.
fn label_at(v: f64, ids: &[u32]) -> String {
    let i = v.round();
    if (v - i).abs() > 1e-6 || i < 0.0 {
        return String::new();
    }
    ids.get(i as usize).map(u32::to_string).unwrap_or_default()
}
