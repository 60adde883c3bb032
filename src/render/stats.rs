//! Per-frame statistics: the CSV of `--stats` and the stacked bar chart of `--plot`
//! (SVG written by hand; PNG drawn into an `image` buffer, labels in an 8×8 bitmap font).

use std::fmt::Write as _;
use std::path::Path;

use super::errors::OptionError;
use super::shade::RayCounts;
use super::RenderError;

/// What a frame did with the static hits and shading a still camera keeps
/// (`--stats`' `kept` column).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kept {
    /// Nothing kept or reused: a camera that moves, several samples a pixel, motion
    /// blur, the GPU.
    #[default]
    None,
    /// Traced and kept for the frames after (a still camera's first frame: several
    /// times the cost of a frame that reuses).
    Fill,
    /// Read what an earlier frame kept (of this frame in flight or copied from another).
    Reuse,
}

impl Kept {
    /// The CSV's word for it.
    pub fn word(self) -> &'static str {
        match self {
            Kept::None => "none",
            Kept::Fill => "fill",
            Kept::Reuse => "reuse",
        }
    }
}

/// Times (milliseconds, wall clock) and ray counts of one rendered frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    pub frame: u32,
    /// Animation time shown, seconds.
    pub time: f64,
    /// Posing the scene and updating the dynamic layer.
    pub update_ms: f64,
    /// Inside intersection batches.
    pub trace_ms: f64,
    /// Making rays and shading.
    pub shade_ms: f64,
    /// Encoding and writing the EXR (on the writer thread, overlapping the next frame).
    pub write_ms: f64,
    pub rays: RayCounts,
    /// CPU time of the render's threads (its pool and the frame loop) over update, trace
    /// and shade; `None` where the system does not say (see `cpu_clock`).
    pub cpu_ms: Option<f64>,
    /// How many threads `cpu_ms` counts (0 with it `None`).
    pub threads: usize,
    /// What the frame did with what a still camera keeps.
    pub kept: Kept,
    /// Samples that took the last frame's sums (a still camera's settled samples).
    pub settled: u64,
}

/// The CSV's first line.
pub(crate) const CSV_HEADER: &str =
    "frame,time,update_ms,trace_ms,shade_ms,write_ms,primary_rays,shadow_rays,secondary_rays,cpu_ms,threads,kept\n";

/// One CSV row (with its line end).
pub(crate) fn csv_row(f: &FrameStats) -> String {
    let cpu = f.cpu_ms.map_or(String::new(), |c| format!("{c:.3}"));
    format!(
        "{},{:.6},{:.3},{:.3},{:.3},{:.3},{},{},{},{cpu},{},{}\n",
        f.frame,
        f.time,
        f.update_ms,
        f.trace_ms,
        f.shade_ms,
        f.write_ms,
        f.rays.primary,
        f.rays.shadow,
        f.rays.secondary,
        f.threads,
        f.kept.word()
    )
}

/// The CSV text: a header, then one row per frame (a render streams the same rows to its
/// file as frames are written).
pub fn stats_csv(frames: &[FrameStats]) -> String {
    let mut s = String::from(CSV_HEADER);
    for f in frames {
        s.push_str(&csv_row(f));
    }
    s
}

/// The rendered frames' figures summed: what a run's report needs, the same size
/// whatever the frame count.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameTotals {
    pub frames: usize,
    pub update_ms: f64,
    pub trace_ms: f64,
    pub shade_ms: f64,
    pub write_ms: f64,
    pub rays: RayCounts,
}

impl FrameTotals {
    pub fn add(&mut self, f: &FrameStats) {
        self.frames += 1;
        self.update_ms += f.update_ms;
        self.trace_ms += f.trace_ms;
        self.shade_ms += f.shade_ms;
        self.write_ms += f.write_ms;
        self.rays.primary += f.rays.primary;
        self.rays.shadow += f.rays.shadow;
        self.rays.secondary += f.rays.secondary;
    }
}

/// Most bars a `--plot` draws (its plot area is 600 pixels wide). A longer run's bars
/// each show the mean of a run of consecutive rendered frames (a power of two of them).
pub const PLOT_BARS: usize = 512;

/// The bars of a `--plot`, gathered as frames are written, never more than
/// [`PLOT_BARS`]: when full, neighbours merge in pairs and each bar takes twice as many
/// frames from then on. A bar is the mean of its frames, labelled by the first.
#[derive(Clone, Debug, Default)]
pub(crate) struct PlotBars {
    /// Sums per bar (`frame`: the bar's first frame), and the frames in each.
    bars: Vec<(FrameStats, u64)>,
    /// Frames a bar takes.
    width: u64,
}

impl PlotBars {
    pub(crate) fn push(&mut self, f: &FrameStats) {
        let width = self.width.max(1);
        match self.bars.last_mut() {
            Some((sum, n)) if *n < width => {
                sum.update_ms += f.update_ms;
                sum.trace_ms += f.trace_ms;
                sum.shade_ms += f.shade_ms;
                sum.write_ms += f.write_ms;
                sum.cpu_ms = sum.cpu_ms.zip(f.cpu_ms).map(|(a, b)| a + b);
                *n += 1;
            }
            _ => {
                if self.bars.len() == PLOT_BARS {
                    self.halve();
                    return self.push(f);
                }
                self.bars.push((*f, 1));
            }
        }
        self.width = width;
    }

    fn halve(&mut self) {
        let merged = self
            .bars
            .chunks(2)
            .map(|c| {
                let mut s = c[0];
                for (o, n) in &c[1..] {
                    s.0.update_ms += o.update_ms;
                    s.0.trace_ms += o.trace_ms;
                    s.0.shade_ms += o.shade_ms;
                    s.0.write_ms += o.write_ms;
                    s.0.cpu_ms = s.0.cpu_ms.zip(o.cpu_ms).map(|(a, b)| a + b);
                    s.1 += n;
                }
                s
            })
            .collect();
        self.bars = merged;
        self.width = self.width.max(1) * 2;
    }

    /// The bars as frames (means), and how many frames a full bar takes.
    pub(crate) fn means(&self) -> (Vec<FrameStats>, u64) {
        let bars = self
            .bars
            .iter()
            .map(|(s, n)| {
                let k = *n as f64;
                FrameStats {
                    update_ms: s.update_ms / k,
                    trace_ms: s.trace_ms / k,
                    shade_ms: s.shade_ms / k,
                    write_ms: s.write_ms / k,
                    cpu_ms: s.cpu_ms.map(|c| c / k),
                    ..*s
                }
            })
            .collect();
        (bars, self.width.max(1))
    }
}

const SERIES: [(&str, [u8; 3]); 4] = [
    ("update", [0x4e, 0x79, 0xa7]),
    ("trace", [0xf2, 0x8e, 0x2b]),
    ("shade", [0x59, 0xa1, 0x4f]),
    ("write", [0xb0, 0x7a, 0xa1]),
];

/// The chart's title (SVG and PNG).
const PLOT_TITLE: &str = "time per frame (ms), stacked";

fn values(f: &FrameStats) -> [f64; 4] {
    [f.update_ms, f.trace_ms, f.shade_ms, f.write_ms].map(|v| {
        if v.is_finite() {
            v.max(0.0)
        } else {
            0.0
        }
    })
}

/// A "nice" axis maximum (1, 2 or 5 × 10^k) at or above `v`, and its tick step.
fn nice_axis(v: f64) -> (f64, f64) {
    let v = if v > 0.0 { v } else { 1.0 };
    let mag = 10f64.powf(v.log10().floor());
    for m in [1.0, 2.0, 5.0, 10.0] {
        if m * mag >= v {
            let top = m * mag;
            return (top, top / 5.0);
        }
    }
    (10.0 * mag, 2.0 * mag)
}

struct Layout {
    w: f64,
    h: f64,
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
    ymax: f64,
    ystep: f64,
}

impl Layout {
    fn new(frames: &[FrameStats]) -> Layout {
        let peak = frames
            .iter()
            .map(|f| values(f).iter().sum::<f64>())
            .fold(0.0, f64::max);
        let (ymax, ystep) = nice_axis(peak);
        Layout {
            w: 800.0,
            h: 400.0,
            left: 70.0,
            right: 130.0,
            top: 30.0,
            bottom: 50.0,
            ymax,
            ystep,
        }
    }
    fn plot_w(&self) -> f64 {
        self.w - self.left - self.right
    }
    fn plot_h(&self) -> f64 {
        self.h - self.top - self.bottom
    }
    fn y(&self, v: f64) -> f64 {
        self.top + self.plot_h() * (1.0 - v / self.ymax)
    }
    /// Left edge and width of bar `i` of `n`.
    fn bar(&self, i: usize, n: usize) -> (f64, f64) {
        let slot = self.plot_w() / n.max(1) as f64;
        let gap = if slot > 4.0 { slot * 0.15 } else { 0.0 };
        (self.left + slot * i as f64 + gap / 2.0, slot - gap)
    }
    /// Frame labels along x: at most about 10.
    fn x_label_every(n: usize) -> usize {
        n.div_ceil(10).max(1)
    }
}

/// The SVG text of the stacked bar chart.
pub fn plot_svg(frames: &[FrameStats]) -> String {
    svg_titled(frames, PLOT_TITLE)
}

fn svg_titled(frames: &[FrameStats], title: &str) -> String {
    let l = Layout::new(frames);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#,
        w = l.w,
        h = l.h
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="18" text-anchor="middle" font-size="14">{title}</text>"#,
        l.left + l.plot_w() / 2.0
    );
    // Y grid and labels.
    let mut v = 0.0;
    while v <= l.ymax * 1.000_001 {
        let y = l.y(v);
        let _ = writeln!(
            s,
            r##"<line x1="{}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            l.left,
            l.left + l.plot_w(),
            l.left - 6.0,
            y + 4.0,
            fmt_num(v)
        );
        v += l.ystep;
    }
    // Bars.
    let n = frames.len();
    for (i, f) in frames.iter().enumerate() {
        let (x, bw) = l.bar(i, n);
        let mut acc = 0.0;
        for ((name, [r, g, b]), val) in SERIES.iter().zip(values(f)) {
            if val <= 0.0 {
                continue;
            }
            let (y0, y1) = (l.y(acc), l.y(acc + val));
            acc += val;
            let _ = writeln!(
                s,
                r##"<rect x="{x:.2}" y="{y1:.2}" width="{bw:.2}" height="{:.2}" fill="#{r:02x}{g:02x}{b:02x}"><title>frame {} {name}: {val:.2} ms</title></rect>"##,
                (y0 - y1).max(0.0),
                f.frame
            );
        }
        if i % Layout::x_label_every(n) == 0 {
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                x + bw / 2.0,
                l.top + l.plot_h() + 16.0,
                f.frame
            );
        }
    }
    // Axes and titles.
    let (x0, y0) = (l.left, l.top + l.plot_h());
    let _ = writeln!(
        s,
        r#"<line x1="{x0}" y1="{}" x2="{x0}" y2="{y0}" stroke="black"/><line x1="{x0}" y1="{y0}" x2="{}" y2="{y0}" stroke="black"/>"#,
        l.top,
        l.left + l.plot_w()
    );
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">frame</text>"#,
        l.left + l.plot_w() / 2.0,
        l.h - 10.0
    );
    let _ = writeln!(
        s,
        r#"<text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">ms</text>"#,
        l.top + l.plot_h() / 2.0,
        l.top + l.plot_h() / 2.0
    );
    // Legend, top to bottom in stacking order reversed (as the bars read).
    for (k, (name, [r, g, b])) in SERIES.iter().rev().enumerate() {
        let y = l.top + 10.0 + 22.0 * k as f64;
        let x = l.w - l.right + 20.0;
        let _ = writeln!(
            s,
            r##"<rect x="{x}" y="{y}" width="14" height="14" fill="#{r:02x}{g:02x}{b:02x}"/><text x="{}" y="{}">{name}</text>"##,
            x + 20.0,
            y + 11.0
        );
    }
    s.push_str("</svg>\n");
    s
}

fn fmt_num(v: f64) -> String {
    if v == v.trunc() {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}").trim_end_matches('0').to_string()
    }
}

/// Side of a label glyph, pixels: the PNG's labels use the 8×8 bitmap font of
/// `font8x8`, which draws every printable ASCII character (the 3×5 font it replaced had
/// 25, so "trace" came out "tra e").
const GLYPH: f64 = 8.0;

/// The 8×8 bitmap of `c`: rows top to bottom, bit 0 the left column. A character outside
/// ASCII is drawn as `?` (the labels are ASCII: numbers, series names, titles).
fn glyph(c: char) -> [u8; 8] {
    let i = if c.is_ascii() {
        c as usize
    } else {
        '?' as usize
    };
    font8x8::legacy::BASIC_LEGACY[i]
}

/// Width of `text` drawn with [`glyph`], pixels.
fn text_width(text: &str) -> f64 {
    text.chars().count() as f64 * GLYPH
}

/// The PNG bytes of the same chart (labels in an 8×8 pixel font).
pub fn plot_png(frames: &[FrameStats]) -> Result<Vec<u8>, image::ImageError> {
    png_titled(frames, PLOT_TITLE)
}

fn png_titled(frames: &[FrameStats], title: &str) -> Result<Vec<u8>, image::ImageError> {
    let l = Layout::new(frames);
    let (w, h) = (l.w as u32, l.h as u32);
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut rect = |x0: f64, y0: f64, x1: f64, y1: f64, c: [u8; 3]| {
        let (x0, x1) = (x0.round().max(0.0) as u32, (x1.round() as u32).min(w));
        let (y0, y1) = (y0.round().max(0.0) as u32, (y1.round() as u32).min(h));
        for y in y0..y1 {
            for x in x0..x1 {
                img.put_pixel(x, y, image::Rgb(c));
            }
        }
    };
    let mut labels: Vec<(f64, f64, String, bool)> = Vec::new(); // x, y, text, right-aligned
    let mut v = 0.0;
    while v <= l.ymax * 1.000_001 {
        let y = l.y(v);
        rect(l.left, y, l.left + l.plot_w(), y + 1.0, [0xdd; 3]);
        labels.push((l.left - 6.0, y - GLYPH / 2.0, fmt_num(v), true));
        v += l.ystep;
    }
    let n = frames.len();
    for (i, f) in frames.iter().enumerate() {
        let (x, bw) = l.bar(i, n);
        let mut acc = 0.0;
        for ((_, c), val) in SERIES.iter().zip(values(f)) {
            rect(x, l.y(acc + val), x + bw.max(1.0), l.y(acc), *c);
            acc += val;
        }
        if i % Layout::x_label_every(n) == 0 {
            let t = f.frame.to_string();
            labels.push((
                x + bw / 2.0 - text_width(&t) / 2.0,
                l.top + l.plot_h() + 8.0,
                t,
                false,
            ));
        }
    }
    let (x0, y0) = (l.left, l.top + l.plot_h());
    rect(x0 - 1.0, l.top, x0, y0, [0; 3]);
    rect(x0 - 1.0, y0, l.left + l.plot_w(), y0 + 1.0, [0; 3]);
    labels.push((
        l.left + l.plot_w() / 2.0 - text_width("frame") / 2.0,
        l.h - 22.0,
        "frame".into(),
        false,
    ));
    labels.push((8.0, l.top + l.plot_h() / 2.0, "ms".into(), false));
    labels.push((
        l.left + l.plot_w() / 2.0 - text_width(title) / 2.0,
        10.0,
        title.into(),
        false,
    ));
    for (k, (name, c)) in SERIES.iter().rev().enumerate() {
        let y = l.top + 10.0 + 22.0 * k as f64;
        let x = l.w - l.right + 20.0;
        rect(x, y, x + 14.0, y + 14.0, *c);
        labels.push((x + 20.0, y + 3.0, (*name).to_string(), false));
    }
    for (x, y, text, right) in labels {
        let x = if right { x - text_width(&text) } else { x };
        for (k, ch) in text.chars().enumerate() {
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        let px = x + k as f64 * GLYPH + col as f64;
                        let py = y + row as f64;
                        rect(px, py, px + 1.0, py + 1.0, [0; 3]);
                    }
                }
            }
        }
    }
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)?;
    Ok(out)
}

/// Plot format from the file's extension; `per_bar` frames (at most) make each bar.
pub(crate) fn plot_bytes(
    path: &Path,
    frames: &[FrameStats],
    per_bar: u64,
) -> Result<Vec<u8>, RenderError> {
    let title = match per_bar {
        0 | 1 => PLOT_TITLE.to_string(),
        n => format!("{PLOT_TITLE}; each bar the mean of {n} frames (the last of fewer)"),
    };
    match plot_kind(path)? {
        PlotKind::Svg => Ok(svg_titled(frames, &title).into_bytes()),
        PlotKind::Png => png_titled(frames, &title).map_err(|source| RenderError::Png {
            path: path.to_path_buf(),
            source,
        }),
    }
}

pub(crate) enum PlotKind {
    Svg,
    Png,
}

pub(crate) fn plot_kind(path: &Path) -> Result<PlotKind, RenderError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("svg") => Ok(PlotKind::Svg),
        Some("png") => Ok(PlotKind::Png),
        _ => Err(OptionError::PlotExtension {
            path: path.to_path_buf(),
        }
        .into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<FrameStats> {
        (0..3)
            .map(|i| FrameStats {
                frame: i,
                time: i as f64 / 24.0,
                update_ms: 1.0,
                trace_ms: 10.0 + i as f64,
                shade_ms: 5.0,
                write_ms: 2.5,
                rays: RayCounts {
                    primary: 100,
                    shadow: 50,
                    secondary: 7,
                },
                cpu_ms: (i != 1).then_some(30.0),
                threads: 2,
                kept: [Kept::Fill, Kept::Reuse, Kept::None][i as usize],
                settled: 0,
            })
            .collect()
    }

    #[test]
    fn csv_rows() {
        let csv = stats_csv(&frames());
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 4);
        assert_eq!(
            lines[1],
            "0,0.000000,1.000,10.000,5.000,2.500,100,50,7,30.000,2,fill"
        );
        // No CPU time known: an empty field.
        assert_eq!(
            lines[2],
            "1,0.041667,1.000,11.000,5.000,2.500,100,50,7,,2,reuse"
        );
        assert!(lines[3].ends_with(",2,none"), "{}", lines[3]);
    }

    /// However many frames, the plot keeps at most PLOT_BARS bars, each the mean of
    /// consecutive frames, and their means weigh every frame once.
    #[test]
    fn plot_bars_stay_bounded_and_average_neighbours() {
        let mut bars = PlotBars::default();
        let n = 5 * PLOT_BARS as u32 + 3;
        for i in 0..n {
            bars.push(&FrameStats {
                frame: i,
                trace_ms: i as f64,
                ..Default::default()
            });
            assert!(bars.bars.len() <= PLOT_BARS);
        }
        let (means, per_bar) = bars.means();
        assert_eq!(per_bar, 8);
        assert_eq!(means.len(), (n as usize).div_ceil(8));
        // Bar k holds frames 8k..8k+8: its first frame and their mean.
        assert_eq!(means[3].frame, 24);
        assert_eq!(means[3].trace_ms, (24..32).sum::<u32>() as f64 / 8.0);
        let last = means.last().unwrap();
        assert_eq!(last.frame, n - n % 8);
        let total: u64 = bars.bars.iter().map(|(_, k)| k).sum();
        assert_eq!(total, n as u64);
        // Few frames: one bar each, as before.
        let mut few = PlotBars::default();
        for f in frames() {
            few.push(&f);
        }
        assert_eq!(few.means(), (frames(), 1));
    }

    #[test]
    fn svg_has_bars_axes_and_legend() {
        let svg = plot_svg(&frames());
        assert_eq!(svg.matches("<rect x=").count(), 3 * 4 + 4);
        for name in ["update", "trace", "shade", "write", "frame"] {
            assert!(svg.contains(&format!(">{name}<")), "{name}");
        }
        assert_eq!(nice_axis(20.5), (50.0, 10.0));
        assert_eq!(nice_axis(0.7), (1.0, 0.2));
        let png = plot_png(&frames()).unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }

    /// Issue 24: the 3×5 font had no 'c', 'n', 'l', ... so "trace" was drawn "tra e".
    #[test]
    fn every_label_character_has_a_glyph_of_its_own() {
        let mut labels: Vec<String> = vec![PLOT_TITLE.into(), "frame".into(), "ms".into()];
        labels.extend(SERIES.iter().map(|(n, _)| n.to_string()));
        labels.extend(["0123456789".into(), fmt_num(0.025), fmt_num(12.5)]);
        let mut seen: Vec<(char, [u8; 8])> = Vec::new();
        for c in labels.iter().flat_map(|l| l.chars()).filter(|c| *c != ' ') {
            let g = glyph(c);
            assert_ne!(g, [0; 8], "{c:?} has no glyph");
            if let Some((d, _)) = seen.iter().find(|(d, h)| *h == g && *d != c) {
                panic!("{c:?} and {d:?} share a glyph");
            }
            seen.push((c, g));
        }
        // All of printable ASCII is drawn, each character differently.
        let printable: Vec<[u8; 8]> = ('!'..='~').map(glyph).collect();
        assert!(printable.iter().all(|g| *g != [0; 8]));
        for (i, g) in printable.iter().enumerate() {
            assert!(
                !printable[i + 1..].contains(g),
                "{:?}",
                (b'!' + i as u8) as char
            );
        }
    }

    #[test]
    fn png_legend_labels_are_drawn_glyph_for_glyph() {
        let png = plot_png(&frames()).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        let l = Layout::new(&frames());
        for (k, (name, _)) in SERIES.iter().rev().enumerate() {
            let x0 = (l.w - l.right + 40.0) as u32;
            let y0 = (l.top + 13.0 + 22.0 * k as f64) as u32;
            for (i, c) in name.chars().enumerate() {
                let g = glyph(c);
                for row in 0..8u32 {
                    for col in 0..8u32 {
                        let ink = img.get_pixel(x0 + 8 * i as u32 + col, y0 + row).0 == [0; 3];
                        let bit = g[row as usize] & (1 << col) != 0;
                        assert_eq!(ink, bit, "{name:?}: {c:?} at row {row}, column {col}");
                    }
                }
            }
        }
    }
}
