//! `study.svg`: the spread of the translational error over the seeds, one
//! column per log on a logarithmic axis (errors of SLAM and odometry span
//! decades): a dot per scored run, the median as a bar, the raw
//! odometry's error as a dashed line and a cross per failed run in a band
//! above the plot.

use std::fmt::Write as _;
use std::path::Path;

use super::report::{Row, Status, Summary};

const LEFT: f64 = 80.0;
const TOP: f64 = 70.0;
const BOTTOM_MARGIN: f64 = 70.0;
const COLUMN: f64 = 150.0;
const HEIGHT: f64 = 420.0;
const DOT: &str = "#1f77b4";
const ODOMETRY: &str = "#d62728";
const FAILED: &str = "#9467bd";

/// The plot of `rows` grouped as `summaries` (one column each).
pub(super) fn plot(summaries: &[Summary], rows: &[Row]) -> String {
    // Wide enough for the title and the legend with one log.
    let width = (LEFT + COLUMN * summaries.len().max(1) as f64 + 30.0).max(420.0);
    let bottom = HEIGHT - BOTTOM_MARGIN;
    let values: Vec<f64> = summaries
        .iter()
        .flat_map(|s| s.errors_m.iter().copied().chain(s.odometry.map(|o| o.trans_m)))
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    let (lo, hi) = decades(&values);
    let y = |v: f64| {
        let v = v.clamp(10f64.powi(lo), 10f64.powi(hi));
        bottom - (v.log10() - f64::from(lo)) / f64::from(hi - lo) * (bottom - TOP)
    };
    let mut t = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{HEIGHT}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{LEFT}\" y=\"18\" font-size=\"14\">Translational error over seeds (relation metric)</text>\n"
    );
    let right = width - 30.0;
    for k in lo..=hi {
        let v = 10f64.powi(k);
        let _ = writeln!(
            t,
            "<line x1=\"{LEFT}\" y1=\"{0:.1}\" x2=\"{right}\" y2=\"{0:.1}\" stroke=\"#ddd\"/>\
             <text x=\"{1}\" y=\"{2:.1}\" text-anchor=\"end\">{v}</text>",
            y(v),
            LEFT - 6.0,
            y(v) + 4.0
        );
    }
    let _ = writeln!(
        t,
        "<line x1=\"{LEFT}\" y1=\"{TOP}\" x2=\"{LEFT}\" y2=\"{bottom}\" stroke=\"black\"/>\
         <line x1=\"{LEFT}\" y1=\"{bottom}\" x2=\"{right}\" y2=\"{bottom}\" stroke=\"black\"/>\n\
         <text x=\"18\" y=\"{0}\" transform=\"rotate(-90 18 {0})\" text-anchor=\"middle\">translational error, m (log scale)</text>\n\
         <text x=\"{LEFT}\" y=\"{1}\" fill=\"{FAILED}\">failed ×</text>",
        (TOP + bottom) / 2.0,
        TOP - 26.0,
    );
    for (i, s) in summaries.iter().enumerate() {
        let cx = LEFT + COLUMN * (i as f64 + 0.5);
        let (x0, x1) = (cx - COLUMN * 0.35, cx + COLUMN * 0.35);
        let name = Path::new(&s.log).file_name().map_or(s.log.clone(), |n| n.to_string_lossy().into_owned());
        let _ = writeln!(
            t,
            "<text x=\"{cx}\" y=\"{0}\" text-anchor=\"middle\">{1}</text>\
             <text x=\"{cx}\" y=\"{2}\" text-anchor=\"middle\" fill=\"grey\">{3} runs, {4} failed</text>",
            bottom + 18.0,
            escape(&name),
            bottom + 34.0,
            s.runs,
            s.failures
        );
        if let Some(o) = s.odometry {
            let _ = writeln!(
                t,
                "<line class=\"odometry\" x1=\"{x0:.1}\" y1=\"{0:.1}\" x2=\"{x1:.1}\" y2=\"{0:.1}\" stroke=\"{ODOMETRY}\" stroke-width=\"1.5\" stroke-dasharray=\"6 4\"><title>raw odometry: {1:.4} m</title></line>",
                y(o.trans_m),
                o.trans_m
            );
        }
        if let Some(m) = s.median_m() {
            let _ = writeln!(
                t,
                "<line class=\"median\" x1=\"{0:.1}\" y1=\"{1:.1}\" x2=\"{2:.1}\" y2=\"{1:.1}\" stroke=\"black\" stroke-width=\"2.5\"><title>median: {m:.4} m</title></line>",
                cx - COLUMN * 0.2,
                y(m),
                cx + COLUMN * 0.2
            );
        }
        let mine: Vec<&Row> = rows.iter().filter(|r| r.log == s.log).collect();
        let step = (COLUMN * 0.5 / mine.len().max(1) as f64).min(10.0);
        for (j, r) in mine.iter().enumerate() {
            let x = cx + (j as f64 - (mine.len() as f64 - 1.0) / 2.0) * step;
            match (r.status, r.accuracy) {
                (Status::Ok, Some(a)) => {
                    let _ = writeln!(
                        t,
                        "<circle class=\"run\" cx=\"{x:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{DOT}\" fill-opacity=\"0.7\"><title>seed {}: {:.4} m</title></circle>",
                        y(a.trans_m),
                        r.seed,
                        a.trans_m
                    );
                }
                (Status::Failed, _) => {
                    let yf = TOP - 30.0;
                    let _ = writeln!(
                        t,
                        "<path class=\"failed\" d=\"M{0:.1},{1:.1}L{2:.1},{3:.1}M{0:.1},{3:.1}L{2:.1},{1:.1}\" stroke=\"{FAILED}\" stroke-width=\"2\"><title>seed {4} failed: {5}</title></path>",
                        x - 4.0,
                        yf - 4.0,
                        x + 4.0,
                        yf + 4.0,
                        r.seed,
                        escape(&r.error)
                    );
                }
                (Status::Ok, None) | (Status::Stopped, _) => {}
            }
        }
    }
    let legend_y = HEIGHT - 12.0;
    let _ = writeln!(
        t,
        "<circle cx=\"{0}\" cy=\"{1}\" r=\"4\" fill=\"{DOT}\"/><text x=\"{2}\" y=\"{3}\">one seed</text>\
         <line x1=\"{4}\" y1=\"{1}\" x2=\"{5}\" y2=\"{1}\" stroke=\"black\" stroke-width=\"2.5\"/><text x=\"{6}\" y=\"{3}\">median</text>\
         <line x1=\"{7}\" y1=\"{1}\" x2=\"{8}\" y2=\"{1}\" stroke=\"{ODOMETRY}\" stroke-dasharray=\"6 4\"/><text x=\"{9}\" y=\"{3}\">raw odometry</text>",
        LEFT,
        legend_y - 4.0,
        LEFT + 8.0,
        legend_y,
        LEFT + 80.0,
        LEFT + 100.0,
        LEFT + 105.0,
        LEFT + 160.0,
        LEFT + 185.0,
        LEFT + 190.0
    );
    t.push_str("</svg>\n");
    t
}

/// The decades (powers of ten) that enclose `values`: at least one.
fn decades(values: &[f64]) -> (i32, i32) {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !lo.is_finite() || !hi.is_finite() {
        return (-2, 0);
    }
    let (lo, hi) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    (lo, hi.max(lo + 1))
}

/// Text safe inside an SVG element or attribute.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_axis_spans_whole_decades_around_the_values() {
        assert_eq!(decades(&[0.05, 0.549]), (-2, 0));
        assert_eq!(decades(&[1.0]), (0, 1));
        assert_eq!(decades(&[]), (-2, 0));
    }
}
