//! Charts for sweeps (plotters): one measure against one variable, a series per combination of
//! the other varied parameters, written as both PNG and SVG.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Points only, unjoined (a scatter of predicted against measured, say).
    pub scatter: bool,
}

pub struct Chart<'a> {
    pub title: String,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: Vec<Series>,
    /// Names for integer x positions when the variable is not numeric.
    pub x_names: Option<Vec<String>>,
}

/// plotters draws text with a font we must supply (no system font lookup in this build):
/// `MESOFLOW_FONT`, else DejaVu Sans where distributions install it.
fn ensure_font() -> Result<(), String> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let mut candidates: Vec<String> = std::env::var("MESOFLOW_FONT").into_iter().collect();
        candidates.extend(
            [
                "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
                "/usr/share/fonts/TTF/DejaVuSans.ttf",
                "/usr/share/fonts/dejavu/DejaVuSans.ttf",
                "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
                "/Library/Fonts/Arial.ttf",
                "C:\\Windows\\Fonts\\arial.ttf",
            ]
            .map(String::from),
        );
        let bytes = candidates
            .iter()
            .find_map(|p| std::fs::read(p).ok())
            .ok_or(
            "no TrueType font found for chart text; install fonts-dejavu-core or set MESOFLOW_FONT",
        )?;
        let leaked: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, leaked)
            .map_err(|_| "the chart font could not be parsed".to_string())
    })
    .clone()
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        lo.abs().max(1.0) * 0.05
    };
    (lo - pad, hi + pad)
}

/// A numeric, positive x spanning more than two decades (timings, counts) is drawn on a log
/// scale: on a linear one the fast cases collapse onto the axis. So is one whose values grow
/// by a factor (ranks 1, 2, 4, 8, 16; samples 1, 4, 16, 64): each step then has its own width.
fn wants_log_x(c: &Chart) -> bool {
    let mut xs: Vec<f64> = c
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .filter(|v| v.is_finite())
        .collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let (Some(&lo), Some(&hi)) = (xs.first(), xs.last()) else {
        return false;
    };
    let geometric = xs.len() >= 3 && xs.windows(2).all(|w| w[1] >= 1.9 * w[0]);
    c.x_names.is_none() && lo > 0.0 && (hi / lo > 100.0 || geometric)
}

/// A positive y spanning more than two decades (ratios from 0.04 to 6, say) is drawn on a log
/// scale too: on a linear one the small values collapse onto the axis.
fn wants_log_y(c: &Chart) -> bool {
    let ys: Vec<f64> = c
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .collect();
    let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    !ys.is_empty() && lo > 0.0 && hi / lo > 100.0
}

/// An axis label with as many decimals as the axis's span needs (an axis of whole numbers
/// reads 2, 4, 8, not 2.000).
fn tick(v: f64, span: f64) -> String {
    let step = span.abs() / 8.0;
    let decimals = if step >= 1.0 || step == 0.0 {
        0
    } else {
        ((-step.log10()).ceil() as usize).min(6)
    };
    format!("{v:.decimals$}")
}

/// A log axis's label: the value itself, three significant digits, no trailing zeros.
fn log_tick(x: f64) -> String {
    let v = 10f64.powf(x);
    let decimals = (2 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Series names in natural order, numbers by value: `pca.rank=2` before `pca.rank=16`.
fn natural_order(a: &str, b: &str) -> std::cmp::Ordering {
    let parts = |s: &str| -> Vec<String> {
        s.split([',', '=', ' '])
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    for (x, y) in parts(a).iter().zip(parts(b).iter()) {
        let ord = match (x.parse::<f64>(), y.parse::<f64>()) {
            (Ok(p), Ok(q)) => p.total_cmp(&q),
            _ => x.cmp(y),
        };
        if ord != std::cmp::Ordering::Equal {
            return ord;
        }
    }
    a.len().cmp(&b.len())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, c: &Chart) -> Result<(), String> {
    let (log_x, log_y) = (wants_log_x(c), wants_log_y(c));
    if log_x || log_y {
        let f = |v: f64, log: bool| if log { v.log10() } else { v };
        let logged = Chart {
            title: c.title.clone(),
            x_label: c.x_label,
            y_label: c.y_label,
            series: c
                .series
                .iter()
                .map(|s| Series {
                    name: s.name.clone(),
                    points: s
                        .points
                        .iter()
                        .map(|p| (f(p.0, log_x), f(p.1, log_y)))
                        .collect(),
                    scatter: s.scatter,
                })
                .collect(),
            x_names: c.x_names.clone(),
        };
        return draw_axes(root, &logged, log_x, log_y);
    }
    draw_axes(root, c, false, false)
}

fn draw_axes<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    c: &Chart,
    log_x: bool,
    log_y: bool,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (x0, x1) = range(c.series.iter().flat_map(|s| s.points.iter().map(|p| p.0)));
    let (y0, y1) = range(c.series.iter().flat_map(|s| s.points.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(&root)
        .caption(&c.title, ("sans-serif", 22))
        .margin(20)
        .x_label_area_size(45)
        .y_label_area_size(75)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let names = c.x_names.clone();
    let x_fmt = move |x: &f64| match &names {
        Some(n) if (x.round() - x).abs() < 1e-9 && *x >= 0.0 => {
            n.get(x.round() as usize).cloned().unwrap_or_default()
        }
        Some(_) => String::new(),
        None if log_x => log_tick(*x),
        None => tick(*x, x1 - x0),
    };
    let x_desc = if log_x {
        format!("{} (log scale)", c.x_label)
    } else {
        c.x_label.to_string()
    };
    let y_desc = if log_y {
        format!("{} (log scale)", c.y_label)
    } else {
        c.y_label.to_string()
    };
    let y_fmt = move |y: &f64| {
        if log_y {
            log_tick(*y)
        } else {
            tick(*y, y1 - y0)
        }
    };
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .draw()
        .map_err(e)?;
    // The legend in the values' order; each series' points joined in the order given (the
    // parameter's, so a trade-off curve is traced along its parameter).
    let mut order: Vec<&Series> = c.series.iter().collect();
    order.sort_by(|a, b| natural_order(&a.name, &b.name));
    for (i, s) in order.into_iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let pts = s.points.clone();
        chart
            .draw_series(LineSeries::new(
                if s.scatter { Vec::new() } else { pts.clone() },
                colour.stroke_width(2),
            ))
            .map_err(e)?
            .label(s.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 4, colour.filled())))
            .map_err(e)?;
    }
    if c.series.len() > 1 || !c.series.first().is_some_and(|s| s.name.is_empty()) {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }
    root.present().map_err(e)
}

/// Writes `<base>.svg` and `<base>.png` (the extension is appended: chart names contain dots).
pub fn write(base: &Path, c: &Chart) -> Result<(), String> {
    ensure_font()?;
    let size = (900u32, 560u32);
    let with = |ext: &str| PathBuf::from(format!("{}.{ext}", base.display()));
    let svg = with("svg");
    draw(SVGBackend::new(&svg, size).into_drawing_area(), c)?;
    let mut rgb = vec![0u8; (size.0 * size.1 * 3) as usize];
    draw(
        BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(),
        c,
    )?;
    let img = image::RgbImage::from_raw(size.0, size.1, rgb).ok_or("chart buffer size")?;
    img.save(with("png")).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_legends_and_scales_read_as_the_data() {
        assert_eq!(tick(4.0, 14.0), "4");
        assert_eq!(tick(0.015, 0.02), "0.015");
        assert_eq!(log_tick(2f64.log10()), "2");
        assert_eq!(log_tick(0.5f64.log10()), "0.5");
        let mut names = vec!["pca.rank=1", "pca.rank=16", "pca.rank=2", "pca.rank=4"];
        names.sort_by(|a, b| natural_order(a, b));
        assert_eq!(
            names,
            ["pca.rank=1", "pca.rank=2", "pca.rank=4", "pca.rank=16"]
        );
        let chart = |xs: &[f64]| Chart {
            title: String::new(),
            x_label: "x",
            y_label: "y",
            series: vec![Series {
                name: String::new(),
                points: xs.iter().map(|&x| (x, 1.0)).collect(),
                scatter: false,
            }],
            x_names: None,
        };
        assert!(wants_log_x(&chart(&[1.0, 2.0, 4.0, 8.0, 16.0])));
        assert!(!wants_log_x(&chart(&[1.0, 2.0, 3.0, 4.0])));
        assert!(wants_log_x(&chart(&[0.01, 0.5, 3.0])));
        let ys = |ys: &[f64]| Chart {
            series: vec![Series {
                name: String::new(),
                points: ys.iter().map(|&y| (1.0, y)).collect(),
                scatter: false,
            }],
            ..chart(&[])
        };
        assert!(wants_log_y(&ys(&[0.04, 0.5, 6.2])));
        assert!(!wants_log_y(&ys(&[0.5, 1.0, 6.2])));
        assert!(!wants_log_y(&ys(&[-1.0, 0.5, 600.0])));
    }
}
