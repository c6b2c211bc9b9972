//! The figures of a report, each as PNG and SVG (plotters' bitmap and SVG
//! backends): recall at 90 % precision (top 5) against the fraction of
//! features used, one curve per rule (the paper's Figs. 5–6); the same per
//! warm-up for the calibrated rules; and the histogram of the fraction of
//! features each query used under one setting (Fig. 7).
//!
//! Text is drawn with a TrueType font loaded at run time (no fontconfig):
//! `$BOWLOC_FONT`, else DejaVu Sans from Debian's `fonts-dejavu-core`
//! (installed by `scripts/setup.sh`) or a few other usual places.

use super::Report;
use super::summary::SettingSummary;
use super::sweep::BASELINE;
use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Where a sans-serif TrueType font is looked for, in order.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// Load and register the font once for the whole process.
fn ensure_font() -> anyhow::Result<()> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let candidates: Vec<PathBuf> = std::env::var_os("BOWLOC_FONT")
            .map(PathBuf::from)
            .into_iter()
            .chain(FONT_PATHS.iter().map(PathBuf::from))
            .collect();
        let path = candidates.iter().find(|p| p.is_file()).ok_or_else(|| {
            format!(
                "no font for the plots: install fonts-dejavu-core (scripts/setup.sh) or set \
                 BOWLOC_FONT to a .ttf file (looked in {})",
                FONT_PATHS.join(", ")
            )
        })?;
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{}: not a usable TrueType font", path.display()))
    })
    .clone()
    .map_err(anyhow::Error::msg)
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A figure that can draw itself on any backend.
trait Figure {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB>;
}

/// Draw `figure` into `<stem>.png` and `<stem>.svg` in `out`.
fn save(
    figure: &impl Figure,
    out: &Path,
    stem: &str,
    size: (u32, u32),
) -> anyhow::Result<Vec<PathBuf>> {
    let png = out.join(format!("{stem}.png"));
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        figure
            .draw(&root)
            .and_then(|()| root.present())
            .map_err(|e| anyhow!("{}: {e}", png.display()))?;
    }
    let svg = out.join(format!("{stem}.svg"));
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        figure
            .draw(&root)
            .and_then(|()| root.present())
            .map_err(|e| anyhow!("{}: {e}", svg.display()))?;
    }
    Ok(vec![png, svg])
}

/// One curve: (fraction of features, recall top-5 @90%P), both in %.
struct Curve {
    name: String,
    points: Vec<(f64, f64)>,
}

fn curve(name: String, settings: &[&SettingSummary]) -> Curve {
    let mut points: Vec<(f64, f64)> = settings
        .iter()
        .map(|s| (100.0 * s.fraction.mean, 100.0 * s.recall90_at(5).mean))
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    Curve { name, points }
}

/// Recall versus fraction of features, with the full search as a line.
struct RecallPanel {
    title: String,
    curves: Vec<Curve>,
    baseline: Option<f64>,
}

impl Figure for RecallPanel {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        let ys = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.1))
            .chain(self.baseline);
        let low = ys.fold(100.0f64, f64::min);
        let y_min = ((low - 5.0) / 10.0).floor().max(0.0) * 10.0;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(55)
            .build_cartesian_2d(0f64..100f64, y_min..100f64)?;
        chart
            .configure_mesh()
            .x_desc("features used (%)")
            .y_desc("recall top-5 at 90% precision (%)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(TRANSPARENT)
            .label_style(("sans-serif", 14))
            .draw()?;
        if let Some(b) = self.baseline {
            chart
                .draw_series(LineSeries::new([(0.0, b), (100.0, b)], BLACK.mix(0.5)))?
                .label("full BoW")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.5)));
        }
        for (i, c) in self.curves.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            chart
                .draw_series(LineSeries::new(c.points.clone(), color.stroke_width(2)))?
                .label(c.name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart.draw_series(c.points.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::MiddleLeft)
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    }
}

/// Several recall panels side by side.
struct Panels(Vec<RecallPanel>);

impl Figure for Panels {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        for (panel, area) in self
            .0
            .iter()
            .zip(root.split_evenly((1, self.0.len().max(1))))
        {
            panel.draw(&area)?;
        }
        Ok(())
    }
}

/// Histogram of the fraction of features used per query.
struct FractionHistogram {
    title: String,
    bins: Vec<usize>,
    mean: f64,
}

impl Figure for FractionHistogram {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        let total = self.bins.iter().sum::<usize>().max(1) as f64;
        let shares: Vec<f64> = self
            .bins
            .iter()
            .map(|&c| 100.0 * c as f64 / total)
            .collect();
        let top = shares.iter().copied().fold(0.0, f64::max).max(1.0) * 1.1;
        let width = 100.0 / self.bins.len().max(1) as f64;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(55)
            .build_cartesian_2d(0f64..100f64, 0f64..top)?;
        chart
            .configure_mesh()
            .x_desc("features used (%)")
            .y_desc("queries × runs (%)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(TRANSPARENT)
            .label_style(("sans-serif", 14))
            .draw()?;
        chart.draw_series(shares.iter().enumerate().map(|(i, &h)| {
            let x = i as f64 * width;
            Rectangle::new([(x, 0.0), (x + width, h)], BLUE.mix(0.6).filled())
        }))?;
        let m = 100.0 * self.mean;
        chart
            .draw_series(LineSeries::new([(m, 0.0), (m, top)], RED.stroke_width(2)))?
            .label(format!("mean {m:.1} %"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    }
}

/// Settings of `rule` at warm-up `w`.
fn settings_of<'a>(report: &'a Report, rule: &str, w: usize) -> Vec<&'a SettingSummary> {
    report
        .settings
        .iter()
        .filter(|s| s.setting.rule.name == rule && s.setting.min_features == w)
        .collect()
}

/// Write every figure of `report` into `out`; returns the files written.
pub fn write_all(report: &Report, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    ensure_font()?;
    let c = &report.config;
    let main = c.warmups.first().copied().unwrap_or(0);
    let baseline = report
        .settings
        .iter()
        .find(|s| s.setting.rule.name == BASELINE)
        .map(|s| 100.0 * s.recall90_at(5).mean);
    let rules: Vec<&String> = c.rules.iter().filter(|r| *r != BASELINE).collect();
    let mut written = Vec::new();

    let curves = rules
        .iter()
        .map(|r| curve((*r).clone(), &settings_of(report, r, main)))
        .filter(|c| !c.points.is_empty())
        .collect();
    let figure = RecallPanel {
        title: format!(
            "{}: recall vs features used (warm-up {main})",
            report.dataset.name
        ),
        curves,
        baseline,
    };
    written.extend(save(&figure, out, "recall_vs_features", (900, 600))?);

    let warmed: Vec<RecallPanel> = rules
        .iter()
        .filter(|r| {
            c.warmups.len() > 1
                && c.warmups
                    .iter()
                    .skip(1)
                    .any(|&w| !settings_of(report, r, w).is_empty())
        })
        .map(|r| RecallPanel {
            title: format!("{r}: warm-up"),
            curves: c
                .warmups
                .iter()
                .map(|&w| curve(format!("w={w}"), &settings_of(report, r, w)))
                .filter(|c| !c.points.is_empty())
                .collect(),
            baseline,
        })
        .collect();
    if !warmed.is_empty() {
        let width = 600 * warmed.len() as u32;
        written.extend(save(&Panels(warmed), out, "warmup", (width, 500))?);
    }

    if let Some(h) = &report.histogram {
        let figure = FractionHistogram {
            title: format!(
                "{}: features used per query, {}",
                report.dataset.name, h.label
            ),
            bins: h.bins.clone(),
            mean: h.mean,
        };
        written.extend(save(&figure, out, "fraction_histogram", (900, 500))?);
    }
    Ok(written)
}
