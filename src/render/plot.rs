//! Small line-plot renderer on top of the `svg` crate: axes with "nice" ticks, labelled axes
//! (always with units), series as polylines, optional circles, legend, equal-aspect option.

use svg::node::element::{Circle, Group, Line, Polyline, Rectangle, Text};
use svg::Document;

/// A named line.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Data points.
    pub points: Vec<(f64, f64)>,
    /// Stroke colour.
    pub color: &'static str,
    /// Dashed stroke.
    pub dashed: bool,
    /// Draw the points as dots (a scatter) instead of a line.
    pub dots: bool,
}

/// One plot panel.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// X axis label with unit.
    pub x_label: String,
    /// Y axis label with unit.
    pub y_label: String,
    /// Lines.
    pub series: Vec<Series>,
    /// Circles (cx, cy, r) in data units, drawn thin grey.
    pub circles: Vec<(f64, f64, f64)>,
    /// Same scale on both axes.
    pub equal_aspect: bool,
    /// The data are log10 of the plotted quantities: ticks fall on decades and read 1e-2, 1e-1, ...
    pub log_axes: bool,
}

/// Tick spacing of 1, 2 or 5 times a power of ten giving about `target` ticks.
pub fn nice_step(span: f64, target: f64) -> f64 {
    let raw = (span / target).max(f64::MIN_POSITIVE);
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let nice = if norm < 1.5 {
        1.0
    } else if norm < 3.5 {
        2.0
    } else if norm < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

fn bounds(panel: &Panel) -> (f64, f64, f64, f64) {
    let mut b = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    let mut grow = |x: f64, y: f64| {
        if x.is_finite() && y.is_finite() {
            b.0 = b.0.min(x);
            b.1 = b.1.max(x);
            b.2 = b.2.min(y);
            b.3 = b.3.max(y);
        }
    };
    for s in &panel.series {
        for &(x, y) in &s.points {
            grow(x, y);
        }
    }
    for &(x, y, r) in &panel.circles {
        grow(x - r, y - r);
        grow(x + r, y + r);
    }
    if !b.0.is_finite() {
        return (0.0, 1.0, 0.0, 1.0);
    }
    if b.1 - b.0 <= 0.0 {
        b.1 = b.0 + 1.0;
    }
    if b.3 - b.2 <= 0.0 {
        b.3 = b.2 + 1.0;
    }
    b
}

fn fmt_axis_tick(v: f64, step: f64, log: bool) -> String {
    if log {
        format!("1e{}", v.round() as i64)
    } else {
        fmt_tick(v, step)
    }
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    // Snap to the tick grid so that -0.0 and rounding residue print as "0".
    let v = (v / step).round() * step + 0.0;
    format!("{v:.decimals$}")
}

/// Renders a panel into the rectangle (x0, y0, w, h) of the document, in pixels.
pub fn render_panel(panel: &Panel, x0: f64, y0: f64, w: f64, h: f64) -> Group {
    let (left, right, top, bottom) = (70.0, 20.0, 40.0, 55.0);
    let (pw, ph) = (w - left - right, h - top - bottom);
    let (mut xmin, mut xmax, mut ymin, mut ymax) = bounds(panel);
    let (mut xs, mut ys) = (nice_step(xmax - xmin, 6.0), nice_step(ymax - ymin, 6.0));
    if panel.equal_aspect {
        let scale = (pw / (xmax - xmin)).min(ph / (ymax - ymin));
        let (cx, cy) = ((xmin + xmax) / 2.0, (ymin + ymax) / 2.0);
        xmin = cx - pw / scale / 2.0;
        xmax = cx + pw / scale / 2.0;
        ymin = cy - ph / scale / 2.0;
        ymax = cy + ph / scale / 2.0;
        let step = nice_step((xmax - xmin).max(ymax - ymin), 7.0);
        xs = step;
        ys = step;
    } else {
        if panel.log_axes {
            xs = xs.max(1.0).round();
            ys = ys.max(1.0).round();
        }
        xmin = (xmin / xs).floor() * xs;
        xmax = (xmax / xs).ceil() * xs;
        ymin = (ymin / ys).floor() * ys;
        ymax = (ymax / ys).ceil() * ys;
    }
    let px = move |x: f64| x0 + left + (x - xmin) / (xmax - xmin) * pw;
    let py = move |y: f64| y0 + top + ph - (y - ymin) / (ymax - ymin) * ph;

    let mut g = Group::new()
        .set("font-family", "sans-serif")
        .set("font-size", 12);
    g = g.add(
        Rectangle::new()
            .set("x", x0 + left)
            .set("y", y0 + top)
            .set("width", pw)
            .set("height", ph)
            .set("fill", "white")
            .set("stroke", "#444"),
    );
    for t in ticks(xmin, xmax, xs) {
        g = g
            .add(
                Line::new()
                    .set("x1", px(t))
                    .set("x2", px(t))
                    .set("y1", y0 + top)
                    .set("y2", y0 + top + ph)
                    .set("stroke", "#ddd"),
            )
            .add(
                Text::new(fmt_axis_tick(t, xs, panel.log_axes))
                    .set("x", px(t))
                    .set("y", y0 + top + ph + 16.0)
                    .set("text-anchor", "middle"),
            );
    }
    for t in ticks(ymin, ymax, ys) {
        g = g
            .add(
                Line::new()
                    .set("x1", x0 + left)
                    .set("x2", x0 + left + pw)
                    .set("y1", py(t))
                    .set("y2", py(t))
                    .set("stroke", "#ddd"),
            )
            .add(
                Text::new(fmt_axis_tick(t, ys, panel.log_axes))
                    .set("x", x0 + left - 6.0)
                    .set("y", py(t) + 4.0)
                    .set("text-anchor", "end"),
            );
    }
    g = g
        .add(
            Text::new(panel.title.clone())
                .set("x", x0 + left + pw / 2.0)
                .set("y", y0 + 22.0)
                .set("text-anchor", "middle")
                .set("font-size", 15)
                .set("font-weight", "bold"),
        )
        .add(
            Text::new(panel.x_label.clone())
                .set("x", x0 + left + pw / 2.0)
                .set("y", y0 + h - 12.0)
                .set("text-anchor", "middle"),
        )
        .add(
            Text::new(panel.y_label.clone())
                .set(
                    "transform",
                    format!(
                        "translate({},{}) rotate(-90)",
                        x0 + 18.0,
                        y0 + top + ph / 2.0
                    ),
                )
                .set("text-anchor", "middle"),
        );
    for &(cx, cy, r) in &panel.circles {
        let rp = r / (xmax - xmin) * pw;
        g = g.add(
            Circle::new()
                .set("cx", px(cx))
                .set("cy", py(cy))
                .set("r", rp)
                .set("fill", "none")
                .set("stroke", "#888"),
        );
    }
    let mut legend_row = 0;
    for s in panel.series.iter() {
        if s.dots {
            for &(x, y) in s
                .points
                .iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
            {
                g = g.add(
                    Circle::new()
                        .set("cx", format!("{:.2}", px(x)))
                        .set("cy", format!("{:.2}", py(y)))
                        .set("r", 2.4)
                        .set("fill", s.color),
                );
            }
        }
        let pts: Vec<String> = s
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|&(x, y)| format!("{:.2},{:.2}", px(x), py(y)))
            .collect();
        let mut line = Polyline::new()
            .set("points", pts.join(" "))
            .set("fill", "none")
            .set("stroke", s.color)
            .set("stroke-width", 1.8);
        if s.dashed {
            line = line.set("stroke-dasharray", "6,4");
        }
        if !s.dots {
            g = g.add(line);
        }
        if s.label.is_empty() {
            continue;
        }
        let ly = y0 + top + 14.0 + 16.0 * legend_row as f64;
        legend_row += 1;
        if s.dots {
            g = g.add(
                Circle::new()
                    .set("cx", x0 + left + 22.0)
                    .set("cy", ly - 4.0)
                    .set("r", 3)
                    .set("fill", s.color),
            );
        } else {
            let mut key = Line::new()
                .set("x1", x0 + left + 10.0)
                .set("x2", x0 + left + 34.0)
                .set("y1", ly - 4.0)
                .set("y2", ly - 4.0)
                .set("stroke", s.color)
                .set("stroke-width", 2);
            if s.dashed {
                key = key.set("stroke-dasharray", "6,4");
            }
            g = g.add(key);
        }
        g = g.add(
            Text::new(s.label.clone())
                .set("x", x0 + left + 40.0)
                .set("y", ly),
        );
    }
    g
}

/// A document of panels side by side, each `w` by `h` pixels.
pub fn document(panels: &[Panel], w: f64, h: f64) -> Document {
    let total_w = w * panels.len() as f64;
    let mut doc = Document::new()
        .set("viewBox", (0, 0, total_w, h))
        .set("width", total_w)
        .set("height", h)
        .add(
            Rectangle::new()
                .set("width", total_w)
                .set("height", h)
                .set("fill", "white"),
        );
    for (i, p) in panels.iter().enumerate() {
        doc = doc.add(render_panel(p, w * i as f64, 0.0, w, h));
    }
    doc
}

/// The most grid lines an axis gets.
const MAX_TICKS: f64 = 100.0;

/// Grid positions: the multiples of `step` from `min` to `max`, computed from their index so
/// that a step tiny against the values cannot stall, and at most [`MAX_TICKS`] of them (none
/// for a degenerate axis).
fn ticks(min: f64, max: f64, step: f64) -> Vec<f64> {
    let (first, last) = ((min / step).ceil(), (max / step + 1e-9).floor());
    if !(first.is_finite() && last.is_finite() && step > 0.0) || last - first > MAX_TICKS {
        return Vec::new();
    }
    let n = (last - first).max(-1.0) as i64;
    (0..=n).map(|i| (first + i as f64) * step).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps_are_1_2_5() {
        assert_eq!(nice_step(10.0, 5.0), 2.0);
        assert_eq!(nice_step(200.0, 6.0), 20.0);
        assert_eq!(nice_step(200.0, 4.0), 50.0);
        assert!((nice_step(0.7, 7.0) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn ticks_are_bounded_even_when_the_step_is_below_the_values_resolution() {
        assert_eq!(ticks(0.0, 10.0, 2.0), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(ticks(-1.0, 1.0, 1.0), vec![-1.0, 0.0, 1.0]);
        // 1 + 1e-20 == 1: a step loop would never advance.
        assert!(ticks(1.0, 1.0 + 1e-12, 1e-20).is_empty());
        assert!(ticks(0.0, 1.0, f64::NAN).is_empty());
    }
}
